#!/bin/bash
# The procedure's manual verification, one test after another, with the standard tools — the
# baseline of bench row 2. Run on a component (in the lab: on the laptop), its peer reachable by
# name over SSH. Prints one "PASS name (seconds)" or "FAIL name: why" line per test; exit 0 when
# every test passed. Every command is bounded by `timeout` (a generous safety net that a healthy
# network never reaches: it does not change the tools' own behaviour).
#
# Environment: PEER (peer's name), SELF (this component's name), PEER_USER (ssh user),
# IP_URL (what-is-my-IP URL), PORT_URL (echoip base URL), PORT1 PORT2 PORT3 (free test ports),
# TALKER LISTENER (the lab's ROS scripts), ROS_PY (ROS's python), TOPIC (a fresh topic prefix),
# CAP (the safety net in seconds, default 60).

set -u
CAP=${CAP:-60}
SSH=(ssh -o BatchMode=yes "$PEER_USER@$PEER")
WORK=$(mktemp -d)
FAILED=0
CHILDREN=()

cleanup() {
    # Our background commands, and what we started on the peer (the lab's computers share this
    # machine's process table and files, so its pid files are read here; by pid, never by name).
    for pid in "${CHILDREN[@]}" $(cat "$WORK"/*.pid 2>/dev/null); do kill "$pid" 2>/dev/null; done
    wait 2>/dev/null
    rm -rf "$WORK"
}
trap cleanup EXIT

now() { echo "${EPOCHREALTIME/[.,]/}"; }   # microseconds, no external command
secs() { printf '%d.%06d' $(( $1 / 1000000 )) $(( $1 % 1000000 )); }
result() {  # name, status (0 = pass), start time, detail
    local took
    took=$(secs $(( $(now) - $3 )))
    if [ "$2" -eq 0 ]; then printf 'PASS %s (%.2f s)\n' "$1" "$took"
    else printf 'FAIL %s: %s (%.2f s)\n' "$1" "$4" "$took"; FAILED=1; fi
}
# Wait (bounded, polling like a person glancing at a terminal) until FILE contains TEXT.
wait_for() {
    local file=$1 text=$2 end=$(( $(date +%s) + CAP ))
    while [ "$(date +%s)" -lt "$end" ]; do
        grep -q "$text" "$file" 2>/dev/null && return 0
        sleep 0.05
    done
    return 1
}

START=$(now)

# 1. ISP: browse the internet, learn the public IP.
t=$(now); ip=$(timeout "$CAP" curl -sS "$IP_URL"); rc=$?
[ $rc -eq 0 ] && [ -n "$ip" ]; result "public-ip($ip)" $? "$t" "curl rc=$rc"

# 2. Router: a listener on a test port, then ask the port checker.
t=$(now)
timeout "$CAP" nc -l "$PORT1" >/dev/null 2>&1 & CHILDREN+=($!)
sleep 0.1  # nc -l prints nothing when ready: a person would simply start it first
ans=$(timeout "$CAP" curl -sS "$PORT_URL/port/$PORT1"); rc=$?
echo "$ans" | grep -q '"reachable": *true'; result "port-check" $? "$t" "curl rc=$rc: $ans"

# 3. Linux: ping, ssh, a netcat chat both ways, by name.
t=$(now); timeout "$CAP" ping -c 1 "$PEER" >/dev/null; result "ping" $? "$t" "no reply"
t=$(now); timeout "$CAP" "${SSH[@]}" true; result "ssh" $? "$t" "ssh failed"

t=$(now)
timeout "$CAP" "${SSH[@]}" "echo \$\$ >$WORK/nc.pid; exec timeout $CAP nc -l $PORT2" \
    >"$WORK/chat_out" 2>&1 & CHILDREN+=($!)
ok=1
for _ in $(seq 100); do  # connect once the peer's listener is up (refused until then)
    if echo "hello from $SELF" | timeout "$CAP" nc -N "$PEER" "$PORT2" 2>/dev/null; then ok=0; break; fi
    sleep 0.05
done
[ $ok -eq 0 ] && wait_for "$WORK/chat_out" "hello from $SELF"; result "nc-out" $? "$t" "no chat"

t=$(now)
timeout "$CAP" nc -l "$PORT3" >"$WORK/chat_in" 2>&1 & CHILDREN+=($!)
sleep 0.1
timeout "$CAP" "${SSH[@]}" "echo hello from $PEER | timeout $CAP nc -N $SELF $PORT3"
wait_for "$WORK/chat_in" "hello from $PEER"; result "nc-in" $? "$t" "no chat"

# 4. ROS: rostopic list, then a talker on one side and a listener on the other, both ways.
t=$(now); topics=$(timeout "$CAP" rostopic list 2>&1)
echo "$topics" | grep -q '^/rosout$'; result "rostopic-list" $? "$t" "$topics"

t=$(now)
timeout "$CAP" "${SSH[@]}" ". ~/.bashrc; echo \$\$ >$WORK/listener.pid; exec timeout $CAP $ROS_PY $LISTENER ${TOPIC}_out" \
    >"$WORK/heard_out" 2>&1 & lpid=$!; CHILDREN+=($lpid)
timeout "$CAP" "$ROS_PY" "$TALKER" "${TOPIC}_out" 10 >/dev/null 2>&1 & tpid=$!; CHILDREN+=($tpid)
wait_for "$WORK/heard_out" "heard: hello from"; rc=$?
kill "$tpid" $(cat "$WORK/listener.pid" 2>/dev/null) 2>/dev/null
result "talker-here-listener-there" $rc "$t" "nothing heard"

t=$(now)
timeout "$CAP" "$ROS_PY" "$LISTENER" "${TOPIC}_in" >"$WORK/heard_in" 2>&1 & lpid=$!; CHILDREN+=($lpid)
timeout "$CAP" "${SSH[@]}" ". ~/.bashrc; echo \$\$ >$WORK/talker.pid; exec timeout $CAP $ROS_PY $TALKER ${TOPIC}_in 10" \
    >/dev/null 2>&1 & tpid=$!; CHILDREN+=($tpid)
wait_for "$WORK/heard_in" "heard: hello from"; rc=$?
kill "$lpid" "$tpid" $(cat "$WORK/talker.pid" 2>/dev/null) 2>/dev/null
result "talker-there-listener-here" $rc "$t" "nothing heard"

echo "ELAPSED $(secs $(( $(now) - START )))"
exit $FAILED
