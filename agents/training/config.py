"""The training configuration: pydantic models, loaded from YAML with strict checking.

Every field has a default and a one-line description (printed by ``crowdnav train
--list-options``, and part of the JSON Schema ``crowdnav schema train`` prints). Loading rejects
unknown keys and wrongly typed values with a :class:`ConfigError` in the style every crowdnav
config file shares (:mod:`crowdnav.config_errors`): ``FILE:LINE: dotted.key: expectation``.

A :class:`TrainConfig` is checked once, when it is built; pass the object along (copies with
``model_copy(update=...)``) rather than its dict, which would be checked again.

Algorithm hyperparameters left at ``None`` take crowdnav's per-algorithm default (see
:data:`crowdnav.agents.sb3.factory.ALGORITHM_DEFAULTS`); anything else SB3 accepts goes in ``algo_kwargs``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Annotated, Any, Literal

from crowdnav.agents.training.seeding import DEMONSTRATION_EPISODES, MAX_SEED, MAX_TRAIN_EPISODES
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainValidator,
    Strict,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from crowdnav.config_errors import ConfigIssue, FieldProblems, YamlProblem, format_issues, read_yaml, validation_issues, yaml_line
from crowdnav.errors import CrowdNavError
from crowdnav.registry import ALGORITHM_NAMES, ENCODER_MODES, algorithm_names, algorithm_spec, modality_names, unknown_name_message
from crowdnav.yaml_input import MAX_DEPTH, YamlLimitError, check_value, read_text_file

__all__ = ["ALGORITHM_NAMES", "ENCODER_MODES", "ConfigError", "DemonstrationConfig", "EncoderConfig", "ExtractorConfig", "TrainConfig",
           "config_from_mapping", "config_to_dict", "describe_fields", "load_config"]


MAX_TIMESTEPS = 1_000_000_000
"""The longest budget in env steps (``timesteps``): 2,000 steps an episode over the MAX_TRAIN_EPISODES training seeds a
run has, days of training on one machine; refused in one line, not when the seeds run out."""


class ConfigError(CrowdNavError, ValueError):
    """A training configuration is invalid; ``str()`` names the file, line and key (``issues``: each problem)."""

    def __init__(self, message: str, issues: list[ConfigIssue] | None = None):
        super().__init__(message)
        self.issues = list(issues or [])

    @classmethod
    def from_issues(cls, source: str, issues: list[ConfigIssue]) -> ConfigError:
        return cls(format_issues(source, issues), issues)


def _known_modality(name: str) -> str:
    if name not in (names := modality_names()):  # read at validation time: users register modalities of their own
        raise ValueError(unknown_name_message("modality", name, names))
    return name


def _known_algorithm(name: Any) -> str:
    """An algorithm name of the registry, read at validation time (:func:`crowdnav.registry.register_algorithm` adds names)."""
    names = algorithm_names()
    if not isinstance(name, str) or name not in names:  # the wording of a Literal's error: "expected one of 'sac', ..."
        raise PydanticCustomError("literal_error", "Input should be {expected}", {"expected": ", ".join(repr(n) for n in names)})
    return name


def _algorithm_enum(schema: dict[str, Any]) -> None:
    """The JSON Schema lists the algorithms registered when it is printed."""
    schema.update(type="string", enum=list(algorithm_names()))


def _modality_enum(schema: dict[str, Any]) -> None:
    """The JSON Schema lists the modalities registered when it is printed (validation reads the registry each time)."""
    schema["items"]["enum"] = list(modality_names())


def _path_text(value: Any) -> Any:
    return str(value) if isinstance(value, PurePath) else value


# Strict scalars: YAML's `true` is no integer and "3" no number; an integer is a fine float.
Int = Annotated[int, Strict()]
Float = Annotated[float, Strict(), Field(allow_inf_nan=False)]
Bool = Annotated[bool, Strict()]
Text = Annotated[str, BeforeValidator(_path_text), Strict()]
MAX_LAYER = 4_096
"""Widest layer, kernel or stride: bounds what a config can make the networks allocate up front."""
MAX_LAYERS = 16
"""Most layers in one list of sizes."""
Size = Annotated[int, Strict(), Field(ge=1, le=MAX_LAYER)]
"""A layer size, kernel or stride (at most :data:`MAX_LAYER`)."""
Sizes = Annotated[list[Size], Field(max_length=MAX_LAYERS)]
"""Layer sizes, one per layer (at most :data:`MAX_LAYERS`)."""
if TYPE_CHECKING:  # a Literal built from the registry at run time is no static type: to mypy they are the strings they hold
    Algorithm = str
    EncoderMode = str
else:  # the registry's names: choices, schema enum and errors agree
    Algorithm = Annotated[str, PlainValidator(_known_algorithm)]
    EncoderMode = Literal[tuple(ENCODER_MODES)]
ModalityName = Annotated[str, Strict(), AfterValidator(_known_modality)]


def option(default: Any, doc: str, **constraints: Any) -> Any:
    """A field with a default (lists and dicts copied per instance by pydantic) and a one-line description."""
    return Field(default, description=doc, **constraints)


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=False)


class ExtractorConfig(_Section):
    """Sizes of the multi-modal encoder (one branch per observation key, concatenated into the latent)."""

    leog_channels: Sizes = option([8, 16, 16], "Output channels of each LEOG convolution (a few layers sized for 60x60 grids).")
    leog_kernels: Sizes = option([4, 3, 3], "Kernel size of each LEOG convolution.")
    leog_strides: Sizes = option([4, 2, 1], "Stride of each LEOG convolution.")
    leog_latent: Int = option(64, "Size of the LEOG encoder's tanh output (the autoencoder's bottleneck).", ge=1, le=MAX_LAYER)
    leog_head: Sizes = option([], "Trainable fully connected layers after the LEOG encoder (also trained in frozen mode).")
    lidar_hidden: Sizes = option([64], "Fully connected layers of the LIDAR branch.")
    lidar_conv_channels: Sizes = option([], "Circular 1-D convolutions (kernel 5, stride 2) before the LIDAR's layers; [] for none.")
    rbf_centres: Int = option(16, "Gaussian RBF centres per low-dimensional input value (goal, closest_obstacle, velocity); 0: no RBF.", ge=0)
    rbf_trainable: Bool = option(False, "Learn the RBF centres and widths (otherwise fixed, evenly spread over the value's range).")
    lowdim_hidden: Sizes = option([32], "Fully connected layers after the RBF layer, per low-dimensional key.")
    table_hidden: Sizes = option([64], "Fully connected layers on a flattened table of rows (the humans modality's nearest humans).")


class EncoderConfig(_Section):
    """How the LEOG encoder is initialised and trained."""

    mode: EncoderMode = option(
        "scratch", "scratch: random start, trained with the agent; frozen: pre-trained, no gradient; finetune: pre-trained start, trained."
    )
    weights: Text | None = option(None, "Pre-trained encoder file (encoder.pt from pretrain-encoder); required by frozen and finetune.")
    precompute: Bool = option(True, "Frozen only: encode the grid once per env step in a wrapper, so the replay buffer stores latents.")


MIN_ACTION_STD, MAX_ACTION_STD = 1e-4, 10.0
"""Bounds of ``demonstrations.action_std``: actions lie in [-1, 1]; beyond, its log is a NaN or an infinity in the making."""
MAX_CLONING_EPOCHS = 10_000


class DemonstrationConfig(_Section):
    """A warm start from the privileged social-force robot before RL (docs/agents.md#demonstrations-warm-start); off by default."""

    episodes: Int = option(0, "Episodes of the social-force robot cloned before training starts (0: off, pure RL); with DAgger, "
                              f"episodes x (1 + dagger_rounds) at most {DEMONSTRATION_EPISODES:,} (the seed band's quarter).",
                           ge=0, le=DEMONSTRATION_EPISODES)
    epochs: Int = option(30, "Passes of behaviour cloning over the demonstrations (each DAgger round too).", ge=1, le=MAX_CLONING_EPOCHS)
    batch_size: Int = option(256, "Minibatch of behaviour cloning.", ge=1, le=1_000_000)
    learning_rate: Float = option(1e-3, "Adam learning rate of behaviour cloning (a fresh optimizer; the algorithm's own is untouched).",
                                  gt=0, le=1)
    action_std: Float = option(0.3, "Gaussian std after cloning, in action units: PPO/A2C's log_std is set to it, SAC's log-std head "
                                    "is cloned towards it.", ge=MIN_ACTION_STD, le=MAX_ACTION_STD)
    value_pretraining: Bool = option(True, "Also fit the value function (PPO/A2C) or the critics at the demonstrated actions "
                                           "(SAC/TD3/DDPG) to the demonstrations' discounted returns.")
    into_replay_buffer: Bool = option(True, "Off-policy: store the demonstration transitions in the replay buffer (ordinary transitions).")
    dagger_rounds: Int = option(0, "DAgger rounds after cloning: the clone drives `episodes` more episodes, the expert labels them, "
                                   "cloning goes on over all of them.", ge=0, le=DEMONSTRATION_EPISODES - 1)


class TrainConfig(_Section):
    """One training run: environment, algorithm, networks, budget and outputs."""

    scenario: Text = option("open_space", "Library scenario name or path to a scenario YAML file.")
    modalities: list[ModalityName] = option(["lidar", "goal"], "Observation keys the agent receives (names in crowdnav.sensors.MODALITIES).",
                                          min_length=1, json_schema_extra=_modality_enum)
    normalize_observations: Bool = option(True, "Scale each float modality by its declared scale ((x - offset) / scale, O(1)); false: raw units.")
    sensors: dict[str, Any] = option({}, "Sensor-setting overrides, e.g. {lidar: {beams: 180}}.")
    overrides: dict[str, Any] = option({}, "Dotted scenario overrides, e.g. {humans.count: 5}.")
    reward_weights: dict[str, Any] = option({}, "Reward preset and weight overrides, e.g. {preset: paper, social: -50} (docs/agents.md#reward).")
    shield: Bool | dict[str, Any] = option(False, "Action-time safety shield from the robot's tracker, pose and map: true, false or "
                                                  "planner settings, e.g. {horizon: 2.0} (docs/agents.md#the-safety-shield).")
    residual: Bool = option(False, "The policy's action corrects the predictive planner's move (the plan modality must be "
                                   "observed): a residual agent (docs/agents.md#agents-that-anticipate-the-crowd).")
    algo: Algorithm = option("sac", "Learning algorithm: a Stable-Baselines3 one or a registered one (crowdnav.registry.ALGORITHM_SPECS).",
                             json_schema_extra=_algorithm_enum)
    agents: Literal["robot", "robots"] = option(
        "robot", "robot: the Gymnasium env's first robot learns; robots: every robot of a multi-robot scenario learns one shared "
                 "PPO policy, one vector row per robot per world (docs/agents.md#several-robots-shared-parameter-ppo).")
    agent_identity: Bool = option(True, "agents: robots: append a one-hot of the robot's index to its observation, so the shared "
                                        "network can tell robots of different kinematics apart.")
    robot_actions: Literal["native", "velocity", "goal_velocity"] = option(
        "native", "agents: robots: native: the network's 2 values are each robot's own action ((vx, vy) holonomic, (speed, turn "
                  "rate) unicycle); velocity / goal_velocity: a desired velocity in the robot's own / its goal's frame (x toward "
                  "the goal) for every robot, which a unicycle tracks (docs/agents.md#several-robots-shared-parameter-ppo).")
    robot_networks: Literal["shared", "per_kind"] = option(
        "shared", "agents: robots: shared: one MLP for every robot; per_kind: one MLP (actor and critic layers) per robot kinematics, "
                  "chosen by the robot one-hot (needs agent_identity).")
    episodes: Int = option(700, "Training length in episodes (the paper trains for 700); ignored when timesteps is set. At most "
                                f"{MAX_TRAIN_EPISODES:,}: a run's training seeds end there (crowdnav.agents.training.seeding).",
                           ge=1, le=MAX_TRAIN_EPISODES)
    timesteps: Int | None = option(None, "Training length in env steps, counted over all worlds (None: the episodes budget). At "
                                         f"most {MAX_TIMESTEPS:,}: 2,000 steps an episode over a run's training seeds.",
                                   ge=1, le=MAX_TIMESTEPS)
    num_envs: Int = option(32, "Worlds collected from at once (the native vector env, docs/agents.md#batched-training); "
                               "1: one env, as the published single-env results were trained.", ge=1, le=4096)
    updates_per_step: Float | None = option(None, "Off-policy with num_envs > 1: gradient steps per env step, the update-to-data "
                                                  "ratio (None: per-algorithm default).", gt=0, le=16)
    n_steps: Int | None = option(None, "On-policy: steps per world in each rollout (None: per-algorithm default).", ge=1, le=1_000_000)
    seed: Int = option(0, "Seed of the networks and of the training episodes (episode i uses seed train_seed(seed, i)).",
                       ge=0, le=MAX_SEED)
    out: Text = option("runs/train", "Output folder: checkpoint, snapshots, episode log, resolved config.")
    net_arch: Sizes | None = option(None, "Hidden layers of the actor and critic heads on top of the latent (None: per-algorithm default).")
    learning_rate: Float | None = option(None, "Optimizer learning rate (None: per-algorithm default).", gt=0)
    learning_rate_schedule: Literal["constant", "linear"] | None = option(
        None, "linear: the learning rate decays to 0 over the budget (timesteps, or an episodes bound); None: per-algorithm default.")
    batch_size: Int | None = option(None, "Minibatch size (None: per-algorithm default; unused by A2C).", ge=1, le=1_000_000)
    buffer_size: Int | None = option(None, "Replay buffer capacity in transitions (off-policy only; None: default).", ge=1, le=10_000_000)
    learning_starts: Int | None = option(None, "Steps of random actions before gradient updates start (off-policy only; None: default).", ge=0)
    gamma: Float | None = option(None, "Discount factor (None: per-algorithm default).", gt=0, le=1)
    n_step_returns: Int | None = option(None, "Off-policy: rewards summed per replay sample before bootstrapping (None: per-algorithm default).",
                                         ge=1)
    reward_scale: Float = option(1.0, "Multiplies the reward the algorithm learns from (SAC's reward scale); logged returns stay in env units.", gt=0)
    action_noise: Float = option(0.1, "Std of the Gaussian exploration noise of TD3 and DDPG, in action units.")
    algo_kwargs: dict[str, Any] = option({}, "Further keyword arguments of the SB3 algorithm, e.g. {tau: 0.01}.")
    policy_kwargs: dict[str, Any] = option({}, "Further SB3 policy_kwargs, e.g. {share_features_extractor: true} (the extractor is crowdnav's).")
    extractor: ExtractorConfig = Field(default_factory=ExtractorConfig, description="Sizes of the multi-modal encoder.")
    encoder: EncoderConfig = Field(default_factory=EncoderConfig, description="LEOG encoder mode and pre-trained weights.")
    demonstrations: DemonstrationConfig = Field(default_factory=DemonstrationConfig,
                                                description="Warm start from the social-force robot's demonstrations (off by default).")
    checkpoint_every: Int = option(50, "Save a resumable checkpoint (and a policy snapshot) every this many episodes.", ge=1)
    checkpoint_every_steps: Int | None = option(None, "With timesteps: save the checkpoint and a snapshot every this many env steps "
                                                      "instead (snapshots/steps_<N>).", ge=1)
    pack_grids: Bool = option(True, "Off-policy: store LEOG grids in the replay buffer at 1 bit per cell (8x less memory than uint8).")
    save_replay_buffer: Bool = option(True, "Store the replay buffer with the checkpoint so a resumed run continues with it.")
    torch_threads: Int = option(1, "torch.set_num_threads for this process.", ge=1)
    device: Text = option("cpu", "torch device: cpu, cuda or auto.")
    progress: Bool = option(True, "Show a progress bar (episodes, success rate, steps/s).")
    tensorboard: Bool = option(False, "Write TensorBoard logs to OUT/tensorboard (needs the tensorboard package).")

    @field_validator("reward_weights")
    @classmethod
    def _known_reward_names(cls, weights: dict[str, Any]) -> dict[str, Any]:
        from crowdnav.scenario.reward_presets import REWARD_PRESETS, REWARD_TERMS, unknown_preset_message

        for key in weights:
            if key != "preset" and key not in REWARD_TERMS:
                raise ValueError(unknown_name_message("reward term", key, ("preset", *REWARD_TERMS)))
        if "preset" in weights and (not isinstance(weights["preset"], str) or weights["preset"] not in REWARD_PRESETS):
            raise ValueError(unknown_preset_message(weights["preset"]))
        return weights

    @model_validator(mode="after")
    def _cross_field_rules(self) -> TrainConfig:
        problems = cross_field_problems(self)  # a module global, looked up per call (tests count validations with it)
        if problems:
            raise FieldProblems(problems)
        return self

def cross_field_problems(config: TrainConfig) -> list[tuple[str, str]]:
    """``(dotted field, problem)`` for the rules that involve several fields (run on every validation)."""
    problems = []
    if config.encoder.mode in ("frozen", "finetune") and not config.encoder.weights:
        problems.append(("encoder.weights", f"encoder mode {config.encoder.mode!r} needs pre-trained weights (crowdnav pretrain-encoder)"))
    if config.encoder.mode != "scratch" and "leog" not in config.modalities:
        problems.append(("encoder.mode", f"{config.encoder.mode!r} applies to the LEOG, but 'leog' is not among the modalities {config.modalities}"))
    if config.checkpoint_every_steps is not None and config.timesteps is None:
        problems.append(("checkpoint_every_steps", "applies to a budget in env steps; set timesteps too (or use checkpoint_every)"))
    if config.updates_per_step is not None and config.num_envs == 1:
        problems.append(("updates_per_step", "applies to batched training (num_envs > 1); one env takes algo_kwargs.train_freq / gradient_steps"))
    optimizer = config.policy_kwargs.get("optimizer_class")
    if optimizer is not None and not callable(optimizer):
        problems.append(("policy_kwargs.optimizer_class", f"a torch optimizer class, which only Python can pass (got {str(optimizer)[:60]!r}); "
                         "leave it out for SB3's Adam and set its options in policy_kwargs.optimizer_kwargs"))
    demonstrations = config.demonstrations
    if demonstrations.episodes * (1 + demonstrations.dagger_rounds) > DEMONSTRATION_EPISODES:
        problems.append(("demonstrations.dagger_rounds", f"{demonstrations.episodes:,} episodes x (1 + {demonstrations.dagger_rounds:,} "
                         f"rounds) exceed the {DEMONSTRATION_EPISODES:,} demonstration seeds of a run (crowdnav.agents.training.seeding)"))
    if demonstrations.episodes and algorithm_spec(config.algo).recurrent:  # cloning fits single steps, not a memory
        problems.append(("demonstrations.episodes", f"{config.algo}'s LSTM policy cannot be warm-started by behaviour cloning; set it to 0"))
    problems.extend(robots_problems(config))
    problems.extend(planner_problems(config))
    extractor = config.extractor
    if not (len(extractor.leog_channels) == len(extractor.leog_kernels) == len(extractor.leog_strides)) or not extractor.leog_channels:
        problems.append(("extractor", "leog_channels, leog_kernels and leog_strides must be non-empty lists of the same length"))
    return problems


def planner_problems(config: TrainConfig) -> list[tuple[str, str]]:
    """The shield's settings and the residual's plan modality, checked as the env will (before any run folder is written)."""
    from crowdnav.planning.shield import shield_settings

    problems = []
    try:
        settings = shield_settings(config.shield)
    except ValueError as error:
        problems.append(("shield", str(error).removeprefix("shield: ")))
    else:
        scenario = _scenario(config) if settings is not None else None
        if scenario is not None and scenario.robots is not None:
            problems.append(("shield", f"shields one robot; {config.scenario!r} declares several (robots:): train it without the shield"))
        elif scenario is not None and settings is not None:
            try:  # the lattice over the horizon at the scenario's time step, bounded before the env allocates it
                settings.window(float(scenario.time_step))
            except ValueError as error:
                problems.append(("shield", str(error).removeprefix("planner settings: ")))
    if config.residual and "plan" not in config.modalities:
        problems.append(("residual", f"the action corrects the planner's move, so modalities must include plan; got {config.modalities}"))
    return problems


def _scenario(config: TrainConfig) -> Any:
    """The config's scenario (with its overrides); None when it does not load (the env reports that)."""
    from crowdnav.scenario.loader import load_scenario

    try:
        return load_scenario(config.scenario, config.overrides)
    except (CrowdNavError, OSError, ValueError):
        return None


def robots_problems(config: TrainConfig) -> list[tuple[str, str]]:
    """What shared-parameter robot training (``agents: robots``, crowdnav.agents.marl.robots) cannot take."""
    if config.agents != "robots":
        changed = [(name, value) for name, value in (("robot_actions", config.robot_actions), ("robot_networks", config.robot_networks))
                   if value != TrainConfig.model_fields[name].default]
        return [(name, f"{value!r} applies to agents: robots (one policy for every robot); set agents: robots or leave it out")
                for name, value in changed]
    problems = []
    if config.robot_actions == "goal_velocity" and "goal" not in config.modalities:
        problems.append(("robot_actions", f"goal_velocity turns commands by the observed goal direction; add goal to modalities {config.modalities}"))
    if config.robot_networks == "per_kind" and not config.agent_identity:
        problems.append(("robot_networks", "per_kind picks each robot's network by its one-hot; set agent_identity: true"))
    shared = [name for name in algorithm_names() if algorithm_spec(name).robots_trainer is not None]
    if config.algo not in shared:  # the registry says which algorithms train one policy for every robot
        problems.append(("algo", f"agents: robots trains a shared policy with {' or '.join(shared)} (their registry entry's "
                                 f"robots_trainer); set algo: {shared[0]} (got {config.algo!r})"))
    if config.demonstrations.episodes:
        problems.append(("demonstrations.episodes", "agents: robots has no warm start from demonstrations; set it to 0"))
    if config.encoder.mode != "scratch" or "leog" in config.modalities:
        problems.append(("modalities", "agents: robots feeds flat observations to an MLP; the LEOG grid and its encoder are not supported"))
    if config.updates_per_step is not None:
        problems.append(("updates_per_step", "applies to off-policy algorithms; agents: robots trains PPO"))
    return problems


# ------------------------------------------------------------------------- loading


def load_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> TrainConfig:
    """Read a YAML config file (``None``: all defaults), apply dotted ``overrides``, check everything once.

    ``overrides`` maps dotted field names to values, e.g. ``{"algo": "td3", "encoder.mode": "frozen"}``.
    """
    document: dict[str, Any] = {}
    root = None
    label = "<defaults>" if path is None else str(path)
    if path is not None:
        try:
            text = read_text_file(path)  # a regular UTF-8 file of bounded size
        except YamlLimitError as error:
            raise ConfigError(f"{label}: {error}") from None
        try:
            loaded, root = read_yaml(text)
        except YamlProblem as problem:
            raise ConfigError.from_issues(label, [problem.issue]) from None
        if loaded is not None and not isinstance(loaded, dict):
            raise ConfigError(f"{label}: expected a mapping of training options at the top level, got {type(loaded).__name__}")
        document = loaded or {}
    for dotted, value in (overrides or {}).items():
        try:  # the limits of a file: a deep path or value would otherwise recurse in validation
            check_value(value, "the value")
            if dotted.count(".") >= MAX_DEPTH:
                raise YamlLimitError(f"a dotted path of {dotted.count('.') + 1:,} parts; expected at most {MAX_DEPTH}")
        except YamlLimitError as error:
            raise ConfigError(f"{label}: {dotted[:60]}: {error}") from None
        node = document
        *parents, last = dotted.split(".")
        for part in parents:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(f"{label}: {dotted}: {part} is not a section")
        node[last] = value
    return config_from_mapping(document, label, root)


def config_from_mapping(document: Mapping[str, Any], source: str = "<mapping>", root: Any = None) -> TrainConfig:
    """Build a :class:`TrainConfig` from a parsed mapping (strict: unknown keys and wrong types raise :class:`ConfigError`).

    ``root``: the ``yaml.compose`` tree of the file, for line numbers.
    """
    try:
        return TrainConfig.model_validate(document)
    except ValidationError as error:
        issues = [ConfigIssue(issue.path, issue.message, yaml_line(root, issue.path)) for issue in
                  validation_issues(error, document, TrainConfig)]
        raise ConfigError.from_issues(source, issues) from None


def config_to_dict(config: TrainConfig) -> dict[str, Any]:
    """Plain dict (YAML-ready) of a config."""
    return config.model_dump()


def describe_fields(cls: type[BaseModel] = TrainConfig, prefix: str = "") -> list[tuple[str, str, str]]:
    """(dotted name, default, description) of every field, nested sections expanded."""
    rows = []
    for name, info in cls.model_fields.items():
        default = info.get_default(call_default_factory=True)
        if isinstance(default, BaseModel):
            rows.extend(describe_fields(type(default), f"{prefix}{name}."))
        else:
            rows.append((f"{prefix}{name}", repr(default), info.description or ""))
    return rows
