"""Reference agents on a track: a finished benchmark configuration's test episodes, shipped beside the baselines.

``crowdnav track reference NAME --agents RESULTS_DIR/CONFIGURATION`` reads the per-seed folders
``seed_K/`` (``meta.json``, ``test_episodes.csv``) that ``crowdnav benchmark`` wrote, and writes to
``OUT/<track>/``:

* ``agent_<experiment>_<configuration>_seed<K>.csv`` per training seed: the rows of the run's
  final evaluation only (the policy as trained to its whole budget), the track's
  :data:`~crowdnav.evaluation.track_reference.COLUMNS`, numbers at 4 decimals;
* one entry per seed in ``reference.json`` (kind ``policy``; the label says what the agent reads
  and its training budget; the training seed; the experiment's commit), so
  ``crowdnav leaderboard --track NAME`` ranks each seed beside the baselines.

Each training seed is its own row: a trained policy is what one training run produced, and
McNemar's test pairs one policy's outcome with another's on the same episode, which rows pooled
over seeds (three outcomes per episode) would not allow. The spread between the seeds' rows is
the seed-to-seed variance a reader expects to see.

With ``played`` (``--played``) the rows are not copied: each seed's final policy is played on the
track's test episodes (:mod:`crowdnav.evaluation.track_played`), so a network trained with perfect
sensing is ranked on a track that differs from its training's in the sensing only (keys under
``sensors.``, e.g. ``figure4_lidar_tracker``); the entry records what differed
(``trained_setting``, the trained values) and which policy played (``played``), and its label says
it (``...; trained with perfect sensing, played through lidar_tracker``).

With ``chosen`` (``--chosen-on-validation``) each seed is read at the snapshot the declared early-stopping rule keeps
(:mod:`crowdnav.evaluation.validation_choice`: the most successes on validation episodes 500,000-500,299, ties to the
later; the stored validation table is read, nothing is played): the protocol's test evaluation at that point, as
``agent_<experiment>_<configuration>_validated_seed<K>.csv``, an entry of its own beside the final evaluation's, its
label naming the snapshot and the rule, so the two are reported apart and ranked apart.

Before writing anything it checks, each refused in one line naming the difference: that the
experiment's setting is the track's (scenario and overrides, time limit, test seeds and count,
observation keys), that every seed the protocol names is finished, that at least
:data:`MIN_SEEDS` seeds were trained, that every seed ran from a clean commit (no ``+dirty`` in
any commit a session of the run recorded), and, where the experiment holds a straight-to-goal
baseline, that its outcomes on the track's first test episodes are the track's current ones (the
episodes of the commit it ran are this version's). It is idempotent: a seed whose file and entry
are already the same is kept; a different result under the same name is refused unless
``force``.
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from crowdnav.evaluation.track import FINGERPRINT_SEEDS, Track, TrackError
from crowdnav.evaluation.track_leaderboard import MAX_TABLE_BYTES, REFERENCE_FILE, read_bounded, read_index
from crowdnav.evaluation.track_played import play_final, played_label
from crowdnav.evaluation.track_reference import AGENT_PREFIX, COLUMNS, DIRTY, publishing_commit, reference_csv

MIN_SEEDS = 3
"""Training seeds a reference agent is published with, at least."""
_INTEGERS = ("test_seed", "steps")
_TEXT = ("outcome", "collision_kind")


def _flat(value: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for key, item in value.items():
            out.update(_flat(item, f"{prefix}.{key}" if prefix else str(key)))
        return out
    return {prefix: value}


def _budget(steps: int | None, episodes: int) -> str:
    if steps is None:
        return f"{episodes} training episodes"
    if steps >= 1_000_000 and steps % 100_000 == 0:
        return f"{steps / 1_000_000:g}M env steps"
    return f"{steps // 1000}k env steps" if steps % 1000 == 0 else f"{steps} env steps"


def _read_rows(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8", newline="") as file:
        return list(csv.DictReader(file))


def check_setting(track: Track, config: Mapping[str, Any], protocol: Mapping[str, Any], where: str, *,
                  sensing: bool = False) -> dict[str, tuple[Any, Any]]:
    """Refuse, in one line naming the first difference, an experiment whose setting is not ``track``'s.

    ``sensing`` (``--played``): the run's ``sensors`` options count as its setting too, and differences
    in keys under ``sensors.`` (the sensing) are allowed: returned, key -> (trained value, the track's).
    """
    from crowdnav.scenario import ScenarioError, load_scenario

    scenario, overrides = str(config.get("scenario")), dict(config.get("overrides") or {})
    if sensing:  # the env's sensor options win over overrides of the same path, as they did in training
        overrides.update({f"sensors.{key}": value for key, value in _flat(config.get("sensors") or {}).items()})
    if scenario != track.scenario:
        raise TrackError(f"{where} ran scenario {scenario}; track {track.name} is {track.scenario}")
    try:
        ran = _flat(load_scenario(scenario, overrides).model_dump(mode="json"))
    except ScenarioError as error:
        raise TrackError(f"{where}: its scenario no longer loads ({str(error).splitlines()[0]})") from None
    fixed = _flat(load_scenario(track.scenario, track.env_options()["overrides"]).model_dump(mode="json"))
    if ran.get("max_steps") != fixed["max_steps"]:
        raise TrackError(f"{where} ran with a time limit of {ran.get('max_steps')} steps; track {track.name}'s is {fixed['max_steps']}")
    differences = [key for key in sorted(set(ran) | set(fixed)) if ran.get(key) != fixed.get(key)]
    allowed = {key: (ran.get(key), fixed.get(key)) for key in differences if sensing and key.startswith("sensors.")}
    refused = [key for key in differences if key not in allowed]
    if refused:
        shown = "; ".join(f"{key}: {json.dumps(ran.get(key))} (track {json.dumps(fixed.get(key))})" for key in refused[:3])
        more = f" and {len(refused) - 3} more" if len(refused) > 3 else ""
        played = " (played, only the sensing may differ: keys under sensors.)" if sensing else ""
        raise TrackError(f"{where} ran another setting than track {track.name}: {shown}{more}{played}")
    base, count = protocol.get("test_seed_base"), protocol.get("test_episodes")
    if (base, count) != (track.test_seed_base, track.test_episodes):
        raise TrackError(f"{where} was tested on {count} episodes from seed {base}; track {track.name} is {track.test_episodes} "
                         f"episodes from seed {track.test_seed_base}")
    track.check_observations(list(config.get("modalities") or []))
    return allowed


def _seed_folders(folder: Path) -> dict[int, Path]:
    from crowdnav.evaluation.storage import SEED_PREFIX

    found = {}
    for path in folder.iterdir() if folder.is_dir() else []:
        suffix = path.name.removeprefix(SEED_PREFIX)
        if path.is_dir() and path.name.startswith(SEED_PREFIX) and suffix.isdigit():
            found[int(suffix)] = path
    return found


def _final_rows(track: Track, run: Path, where: str, point: int | None = None) -> tuple[list[dict[str, Any]], dict[str, str]]:
    """The final evaluation's rows (typed for :func:`reference_csv`), and its first raw row; ``point``: the evaluation after
    that many training episodes instead."""
    from crowdnav.evaluation.storage import TEST_FILE

    rows = _read_rows(run / TEST_FILE) if (run / TEST_FILE).is_file() else []
    if not rows or "evaluation" not in rows[0]:
        raise TrackError(f"{where}: no per-episode table ({TEST_FILE} with an evaluation column)")
    if point is None:
        last = max(int(row["evaluation"]) for row in rows)
        final = [row for row in rows if int(row["evaluation"]) == last]
    else:
        final = [row for row in rows if int(row["training_episodes"]) == point]
    seeds = [int(row["test_seed"]) for row in final]
    if sorted(seeds) != track.seeds:
        raise TrackError(f"{where}: its {'final ' if point is None else ''}evaluation played {len(seeds)} rows of test seeds "
                         f"{min(seeds, default='-')}-{max(seeds, default='-')}; track "
                         f"{track.name} is one row per seed {track.seeds[0]}-{track.seeds[-1]}")
    typed = []
    for row in sorted(final, key=lambda row: int(row["test_seed"])):
        missing = [column for column in COLUMNS if column not in row]
        if missing:
            raise TrackError(f"{where}: {TEST_FILE} has no column {missing[0]}")
        typed.append({column: int(row[column]) if column in _INTEGERS else row[column] if column in _TEXT else float(row[column])
                      for column in COLUMNS})
    return typed, final[0]


def _straight_check(track: Track, folder: Path) -> str:
    """Compare the experiment's straight-to-goal baseline with the track's on its first test seeds; what was checked."""
    from crowdnav.evaluation.baselines import BASELINE_PREFIX, scripted_policy
    from crowdnav.evaluation.rollout import HeldOutEpisodes
    from crowdnav.evaluation.storage import TEST_FILE

    tables = sorted((folder.parent / f"{BASELINE_PREFIX}straight").rglob(TEST_FILE))
    if not tables:
        return "not cross-checked (the experiment has no straight-to-goal baseline)"
    recorded = {int(row["test_seed"]): row for row in _read_rows(tables[0])}
    seeds = [seed for seed in track.seeds[:FINGERPRINT_SEEDS] if seed in recorded]
    played = HeldOutEpisodes(track.env_options(["goal"]), seeds)
    try:
        now = played.run(scripted_policy("straight"), privileged=True)
    finally:
        played.close()
    for row in now:
        then = recorded[int(row["test_seed"])]
        if (then["outcome"], then["collision_kind"], int(then["steps"])) != (row["outcome"], row["collision_kind"], int(row["steps"])):
            raise TrackError(f"{folder}: its episodes are not track {track.label}'s: straight-to-goal on test seed {row['test_seed']} "
                             f"ended {then['outcome']} after {then['steps']} steps in the experiment and {row['outcome']} after "
                             f"{row['steps']} now (the simulator changed since its commit); train it again on this version")
    return f"straight-to-goal as the track's on its first {len(seeds)} test episodes"


def read_agents(track: Track, folder: str | Path, *, played: bool = False, chosen: bool = False,
                log: Callable[[str], None] = print) -> list[tuple[dict[str, Any], str]]:
    """Check an experiment configuration folder against ``track``; (entry, CSV text) per training seed.

    ``played``: each seed's final policy is played on the track (:mod:`crowdnav.evaluation.track_played`), whose
    setting may differ from its training's in the sensing only, instead of its recorded final evaluation copied.
    ``chosen``: each seed's test evaluation at the snapshot chosen on validation episodes (module docstring).
    """
    from crowdnav.evaluation.storage import META_FILE, read_json
    from crowdnav.evaluation.validation_choice import VALIDATION_EPISODES, VALIDATION_SEED_BASE, stored_choice

    if played and chosen:
        raise TrackError("--played plays each seed's final policy; --chosen-on-validation copies the chosen snapshot's recorded "
                         "evaluation: one or the other")

    folder = Path(folder)
    runs = _seed_folders(folder)
    if not runs:
        raise TrackError(f"{folder}: no seed_K folders: name a finished `crowdnav benchmark` configuration (RESULTS_DIR/CONFIGURATION)")
    metas = {}
    for seed, run in sorted(runs.items()):
        meta = read_json(run / META_FILE) if (run / META_FILE).is_file() else {}
        if meta.get("status") != "complete":
            raise TrackError(f"{run} is not finished (no complete {META_FILE}); finish the experiment first (crowdnav benchmark resumes it)")
        if "config" not in meta:
            raise TrackError(f"{run} is not a trained run of `crowdnav benchmark` (no training config in {META_FILE})")
        metas[seed] = meta
    first = metas[min(metas)]
    protocol = first.get("protocol", {})
    expected = list(range(int(protocol.get("seeds", 0))))
    if sorted(metas) != expected:
        missing = sorted(set(expected) - set(metas))
        raise TrackError(f"{folder}: the protocol trains seeds {expected[0] if expected else '-'}-{expected[-1] if expected else '-'}, "
                         f"and {'seed ' + str(missing[0]) + ' is missing' if missing else 'the folders are ' + str(sorted(metas))}")
    if len(metas) < MIN_SEEDS:
        raise TrackError(f"{folder}: {len(metas)} training seed{'s' if len(metas) != 1 else ''}; reference agents are published with at "
                         f"least {MIN_SEEDS} (train more: protocol seeds: {MIN_SEEDS})")
    sensing: dict[int, dict[str, tuple[Any, Any]]] = {}
    for seed, meta in sorted(metas.items()):
        where = f"{folder.parent.name}/{folder.name}/seed_{seed}"
        for key in ("experiment", "configuration", "label"):
            if meta.get(key) != first.get(key):
                raise TrackError(f"{where}: its {key} is {meta.get(key)!r}, seed_{min(metas)}'s {first.get(key)!r}: not one configuration")
        commits = [str(commit) for commit in meta.get("git_commits") or [meta.get("git_commit")]]
        if any(commit in ("None", "unknown", "") or commit.endswith(DIRTY) for commit in commits):
            raise TrackError(f"{where} ran from {', '.join(commits)}: reference agents are published only from experiments run from a "
                             "clean commit (no uncommitted changes); run it again from one")
        sensing[seed] = check_setting(track, meta["config"], meta.get("protocol", {}), where, sensing=played)
    checked = _straight_check(track, folder)
    trained = played_label(sensing[min(sensing)]) if played else ""
    log(f"{track.name}: {folder}: the track's setting{' but its sensing (' + trained + ')' if trained else ''}; {len(metas)} seeds "
        f"finished from clean commits; episodes {checked}")
    out = []
    for seed, meta in sorted(metas.items()):
        where = f"{folder.parent.name}/{folder.name}/seed_{seed}"
        choice: dict[str, Any] = {}
        if chosen:
            try:
                point, validation = stored_choice(runs[seed])
            except ValueError as error:
                raise TrackError(f"{where}: {error}") from None
            choice = {"seed_base": VALIDATION_SEED_BASE, "episodes": VALIDATION_EPISODES, "kept": point,
                      "validation_successes": {str(key): value for key, value in validation.items()}}
        rows, raw = _final_rows(track, runs[seed], where, choice.get("kept"))
        if played:
            log(f"{track.name}: playing {where}'s final policy on {track.test_episodes} episodes")
            rows, policy = play_final(track, runs[seed], meta, raw, where)
        config = meta["config"]
        modalities = list(config.get("modalities") or [])
        steps = int(raw["training_steps"]) if raw.get("training_steps", "") not in ("", "nan") else None
        budget = _budget(steps, int(raw.get("training_episodes") or 0))
        label = str(meta["label"])
        if not all(key.replace("_", " ") in label.lower() for key in modalities):
            label = f"{label}, reads {', '.join(modalities)}"
        validated = "_validated" if chosen else ""
        name = re.sub(r"[^A-Za-z0-9_.-]", "_", f"{AGENT_PREFIX}{meta['experiment']}_{meta['configuration']}{validated}_seed{seed}")
        observations = ", ".join(modalities) + ("; shield: the humans its sensors report + the map" if config.get("shield") else "")
        success = sum(row["outcome"] == "success" for row in rows) / len(rows)
        how = played_label(sensing[seed]) if played else (
            f"the snapshot after {choice['kept']:,} episodes, chosen on validation episodes {VALIDATION_SEED_BASE:,}-"
            f"{VALIDATION_SEED_BASE + VALIDATION_EPISODES - 1:,}" if chosen else "")
        entry = {"name": name, "label": f"{label} ({budget}, seed {seed}{'; ' + how if how else ''})", "kind": "policy",
                 "observations": observations,
                 "file": f"{name}.csv", "episodes": len(rows), "success": round(success, 4), "experiment": meta["experiment"],
                 "configuration": meta["configuration"], "seed": seed, "algo": config.get("algo"), "modalities": modalities,
                 "training_steps": steps, "training_episodes": int(raw.get("training_episodes") or 0),
                 "experiment_commit": meta["git_commit"], "episodes_checked": checked,
                 **({"experiment_commits": meta["git_commits"]} if len(meta.get("git_commits") or []) > 1 else {}),
                 **({"played": policy, "trained_setting": {key: value for key, (value, _) in sensing[seed].items()}} if played else {}),
                 **({"validation_choice": choice} if chosen else {})}
        out.append((entry, reference_csv(rows)))
    return out


def write_agents(track: Track, folders: list[str | Path], out: str | Path, *, allow_dirty: bool = False, force: bool = False,
                 played: bool = False, chosen: bool = False, log: Callable[[str], None] = print) -> Path:
    """Add every seed of every experiment configuration in ``folders`` to ``out/<track>/``; returns that folder.

    ``played``: their final policies played on the track (:func:`read_agents`), not their recorded evaluations;
    ``chosen``: their snapshots chosen on validation episodes, as entries of their own.
    """
    from crowdnav.evaluation.storage import atomic_write_text

    from crowdnav import __version__

    target = Path(out) / track.name
    commit = publishing_commit(Path(out), allow_dirty)
    index = target / REFERENCE_FILE
    document: dict[str, Any] = read_index(index) if index.is_file() else {
        "track": track.identity(), "git_commit": commit, "crowdnav": __version__, "test_episodes": track.test_episodes,
        "entries": [], "skipped": []}
    if document.get("track") != track.identity():
        recorded = document.get("track") or {}
        raise TrackError(f"{index} holds results of track {recorded.get('name')} v{recorded.get('version')}, not {track.label}: "
                         f"write the baselines of this version first (crowdnav track reference {track.name} --force)")
    # every check before any write
    agents = [pair for folder in folders for pair in read_agents(track, folder, played=played, chosen=chosen, log=log)]
    names = [entry["name"] for entry, _ in agents]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise TrackError(f"two of the configurations named are the same experiment and configuration ({twice[0]}): name each once")
    current = {entry["name"]: entry for entry in document["entries"]}
    def same(entry: dict[str, Any], text: str) -> bool | None:
        """True: this result is there already; False: a different one is; None: nothing is."""
        before, path = current.get(entry["name"]), target / entry["file"]
        if before is None and not path.is_file():
            return None
        return before is not None and {**before, "checked_with": None} == {**entry, "checked_with": None} and path.is_file() \
            and read_bounded(path, MAX_TABLE_BYTES) == text

    for entry, text in agents:
        if same(entry, text) is False and not force:
            raise TrackError(f"{target / entry['file']} already holds a different result of {entry['name']} (another experiment, commit "
                             "or label); --force replaces it")
    for entry, text in agents:
        if same(entry, text) and not force:
            log(f"{track.name}: {entry['name']} kept (the same result)")
            continue
        atomic_write_text(target / entry["file"], text)
        current[entry["name"]] = {**entry, "checked_with": commit}
        document["entries"] = [item for item in document["entries"] if not item["name"].startswith(AGENT_PREFIX)] + \
            [current[name] for name in sorted(current) if name.startswith(AGENT_PREFIX)]
        atomic_write_text(index, json.dumps(document, indent=2, sort_keys=True) + "\n")  # after each one: resumable
        log(f"{track.name}: {entry['name']} success {entry['success']:.0%} on {entry['episodes']} episodes ({entry['label']})")
    target.mkdir(parents=True, exist_ok=True)
    if not index.is_file():
        atomic_write_text(index, json.dumps(document, indent=2, sort_keys=True) + "\n")
    return target
