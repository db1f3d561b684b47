"""The troubleshooting advisor: rules over check results -> what it means, what to do, where to go.

Where things live:

- :mod:`.engine`: :class:`Finding`, :class:`Hit`, :class:`Rule`, the :func:`rule` decorator
  and registry, :func:`advise` (evaluate, supersede, catch-alls, sort);
- :mod:`.evidence`: :class:`Evidence` (what a rule reads: results, settings, the checks'
  declared data) and the helpers several steps' rules share;
- :mod:`.isp`, :mod:`.router`, :mod:`.linux` (:mod:`.names` for names and the hosts file),
  :mod:`.ros` (:mod:`.ros2` for ROS 2, :mod:`.ros2_link` for the link measured, ros2.link's
  and ros.link's, :mod:`.rosbridge` for web clients): the rules, one module per step,
  named like the checks whose data they read (Table 1 and security.exposed are the router's;
  :mod:`.router_upnp` reads router.upnp, the modem's own word; :mod:`.security` reads
  security.ssh_auth and security.outsider, what a stranger gets; :mod:`.relay_tunnel` reads
  relay.tunnel, this component's SSH tunnel on the relay);
- :mod:`.order`: :data:`RULE_ORDER`, the one list that orders findings, docs and ``--ids``;
- :mod:`.docs`: docs/TROUBLESHOOTING.md (:func:`render_rules_markdown`);
- ``__main__``: ``python -m rosnet_tui.core.advisor [--markdown | --ids]``.

The TUI's Advisor pane, ``rosnet-tui check``/``report`` and the docs all read the same rules.
"""

from __future__ import annotations

from rosnet_tui.core.advisor import (  # noqa: F401  (declare the rules)
    firewall,
    isp,
    linux,
    names,
    relay,
    relay_tunnel,
    ros,
    ros2,
    ros2_link,
    ros2_tls,
    rosbridge,
    router,
    router_upnp,
    security,
)
from rosnet_tui.core.advisor.docs import render_rules_markdown
from rosnet_tui.core.advisor.engine import (
    CATCH_ALL_IDS,
    RULES,
    Finding,
    Hit,
    Rule,
    advice_by_check,
    advise,
    all_rules,
    first_failure,
    rule,
    rule_by_id,
    seal,
)
from rosnet_tui.core.advisor.evidence import FORWARD_RANGE, Evidence, RuleOrderError, uri_host
from rosnet_tui.core.advisor.order import RULE_ORDER
from rosnet_tui.core.advisor.router import T1
from rosnet_tui.core.procedure import SEVERITIES, step_title

seal(RULE_ORDER)

# The names this module had before it became a package.

__all__ = ["CATCH_ALL_IDS", "FORWARD_RANGE", "RULES", "RULE_ORDER", "SEVERITIES",
           "T1", "Evidence", "Finding", "Hit", "Rule", "RuleOrderError", "advice_by_check",
           "advise", "all_rules", "first_failure", "render_rules_markdown", "rule",
           "rule_by_id", "step_title", "uri_host"]
