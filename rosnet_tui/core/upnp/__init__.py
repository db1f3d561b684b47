"""Port forwards the modem makes itself, on request from this machine: UPnP IGD, NAT-PMP, PCP.

- :mod:`.wire`: SSDP, a bounded HTTP client, guarded XML, the errors (a malformed or hostile
  answer is refused, never half-used);
- :mod:`.igd`: UPnP IGD's description and SOAP actions; :mod:`.pmp`: NAT-PMP and PCP;
- :mod:`.modem`: find the default gateway's protocols at once, one :class:`Modem` over all of
  them, with the safety rules (this machine only, ports from 1024, bounded leases);
- :mod:`.forwards`: what the settings need, mapping with consent (all or nothing), refusals in
  words (carrier-grade NAT, conflicts, secure mode), unmapping ours only, lease renewal;
- :mod:`.journal`: forwards in the undo journal, with the modem's identity.

rosnet-tui speaks these protocols itself rather than through miniupnpc so that every limit (time
for the whole exchange, answer size, which host may be contacted) is its own and tested.
"""

from rosnet_tui.core.upnp.modem import Forward, Modem, find_modem
from rosnet_tui.core.upnp.wire import HostileAnswer, ModemError, NoAnswer, Refused

__all__ = ["Forward", "HostileAnswer", "Modem", "ModemError", "NoAnswer", "Refused", "find_modem"]
