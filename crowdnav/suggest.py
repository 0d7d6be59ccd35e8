"""The one wording of unknown names, with a "did you mean" hint (configs, scenarios, the CLI).

At the bottom of the package (it imports nothing of crowdnav), so every layer can use it.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def did_you_mean(name: object, valid: Iterable[str]) -> str:
    """``"; did you mean 'sac'?"`` when a valid name is close to ``name``, else ``""``."""
    close = difflib.get_close_matches(str(name), list(valid), n=1)
    return f"; did you mean '{close[0]}'?" if close else ""


def unknown_name_message(what: str, name: object, valid: Iterable[str]) -> str:
    """E.g. ``unknown algorithm 'sca'; did you mean 'sac'? expected one of: sac, td3, ddpg, a2c, ppo``."""
    valid = list(valid)
    hint = did_you_mean(name, valid) or ";"
    return f"unknown {what} {name!r}{hint} expected one of: {', '.join(valid)}"
