"""The SARL-style agent's options (``algo_kwargs``) checked one by one and as totals, before anything is allocated.

Every size-like option is bounded on its own (:data:`INTEGER_OPTIONS`), and the totals they multiply into are bounded
as the SB3 runs' are (docs/security.md, "Bounds on totals"): the value networks' parameters (network and target
copy, every ensemble member) by :data:`crowdnav.agents.networks.size.MAX_PARAMETERS`, counted here by arithmetic
(:func:`network_parameters`, exact: tests/agents/test_sarl_bounds.py compares it with built networks), and the replay
memory and the demonstrations by :data:`MAX_MEMORY_BYTES`. A checkpoint's ``state.json`` options go through the same
checks before its networks are built (:mod:`crowdnav.agents.sarl.files`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from crowdnav.agents.networks.size import check_parameters, mlp
from crowdnav.agents.sarl.lookahead import HUMAN_FEATURES, STATIC_FEATURES
from crowdnav.agents.training.config import ConfigError

INTEGER_OPTIONS: dict[str, tuple[int, int]] = {
    "width": (1, 4096),
    "batch_size": (1, 100_000),
    "updates_per_episode": (1, 10_000),
    "target_update_every": (1, 1_000_000),
    "memory_size": (1, 10_000_000),
    "epsilon_decay_episodes": (0, 1_000_000),
    "imitation_episodes": (0, 250_000),
    "imitation_epochs": (0, 10_000),
    "lookahead_depth": (1, 2),
    "lookahead_width": (1, 81),  # the action set's size
    "ensemble": (1, 8),
}
"""Integer options and their inclusive bounds, each refused outside them in one line."""

MAX_MEMORY_BYTES = 1 << 30
"""Most bytes the replay memory (all ``memory_size`` transitions, both states) or the demonstrations may take: 1 GiB.
The published room runs' 300,000 transitions of 10 humans and 16 walls take about 330 MB."""

MAX_ROWS = 100_000
"""Most tracked humans or static shapes a checkpoint may declare (a tracker's rows; crowdnav's sensors give tens)."""


def check_options(options: Mapping[str, Any], name: str, where: str = "algo_kwargs") -> None:
    """ConfigError (one line, ``where.option``) for an option of the wrong kind or outside its bounds."""
    for option, (low, high) in INTEGER_OPTIONS.items():
        value = options[option]
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ConfigError(f"{where}.{option}: {name!r} takes an integer from {low} to {high}, got {_shown(value)}")
    for option in ("epsilon_start", "epsilon_end"):
        value = options[option]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
            raise ConfigError(f"{where}.{option}: {name!r} takes a rate from 0 to 1, got {_shown(value)}")
    margin = options["human_margin"]
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not 0.0 <= margin <= 1.0:
        raise ConfigError(f"{where}.human_margin: {name!r} takes metres from 0 to 1, got {_shown(margin)}")
    if not isinstance(options["value_bound"], bool):
        raise ConfigError(f"{where}.value_bound: {name!r} takes true or false, got {_shown(options['value_bound'])}")
    if not isinstance(options["imitation_teacher"], str):
        raise ConfigError(f"{where}.imitation_teacher: {name!r} takes a teacher's name, got {_shown(options['imitation_teacher'])}")


def network_parameters(width: int, members: int, room: bool, robot_features: int) -> int:
    """Parameters of one :func:`crowdnav.agents.sarl.network.value_network` (without its target copy)."""
    half = max(width // 2, 1)

    def pool(entity_features: int) -> int:
        return (mlp(robot_features + entity_features, [width, half])[0] + mlp(half, [width, half])[0]
                + mlp(2 * half, [width], 1)[0])

    value = mlp(robot_features + half * (2 if room else 1), [width, width], 1)[0]
    return members * (pool(HUMAN_FEATURES) + value + (pool(STATIC_FEATURES) if room else 0))


def transition_bytes(humans: int, statics: int, robot_features: int) -> int:
    """Bytes of one replay transition (:class:`crowdnav.agents.sarl.memory.ReplayMemory`): both states, reward, terminal."""
    return 4 * (2 * (robot_features + humans * HUMAN_FEATURES + statics * STATIC_FEATURES) + 2)


def check_sizes(options: Mapping[str, Any], humans: int, statics: int, robot_features: int, max_steps: int | None,
                where: str = "algo_kwargs") -> None:
    """ConfigError (one line, ``where.option``) where the networks, the replay memory or the demonstrations would exceed
    their totals. ``max_steps``: the episode length, which bounds a teacher episode's steps (None: demonstrations unchecked).
    """
    width, members = int(options["width"]), int(options["ensemble"])
    total = 2 * network_parameters(width, members, statics > 0, robot_features)  # the value network and its target
    check_parameters(total, f"{where}.width", f"sarl, width {width}" + (f", ensemble {members}" if members > 1 else ""))
    row = transition_bytes(humans, statics, robot_features)
    memory = int(options["memory_size"]) * row
    if memory > MAX_MEMORY_BYTES:
        raise ConfigError(f"{where}.memory_size: {int(options['memory_size']):,} transitions of {row:,} bytes "
                          f"({humans} humans, {statics} static shapes) take {_gib(memory)}, more than the {_gib(MAX_MEMORY_BYTES)} "
                          "a SARL replay memory may take (crowdnav.agents.sarl.options); use a smaller memory_size")
    demonstrations = int(options["imitation_episodes"]) * (max_steps or 0) * (row // 2)
    if demonstrations > MAX_MEMORY_BYTES:
        raise ConfigError(f"{where}.imitation_episodes: {int(options['imitation_episodes']):,} teacher episodes of up "
                          f"to {max_steps:,} steps could take {_gib(demonstrations)}, more than the {_gib(MAX_MEMORY_BYTES)} the "
                          "demonstrations may take (crowdnav.agents.sarl.options); use fewer imitation_episodes")


def _gib(size: int) -> str:
    return f"{size / (1 << 30):,.2f} GiB"


def _shown(value: Any) -> str:
    """A value as an error line shows it: its repr, cut short (a tampered file may hold anything)."""
    return repr(value)[:40]
