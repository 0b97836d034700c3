"""The underwater grasp task, for a batch of B episodes at once: scenes drawn at reset, actions mapped to natural
curvature, observations, reward terms, success and termination. Pure NumPy over the physics core; the Gymnasium
environments (:mod:`soft_gripper_env.env`) are thin layers over :class:`GraspBatch`, so one environment and any
vector of them run the same code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import NamedTuple

import numpy as np

from .physics import (
    DEFAULT_FRICTION,
    NATURAL_CURVATURE_LIMIT,
    PAPER_BALL,
    ContactSettings,
    Current,
    Fluid,
    Gravity,
    GripperDesign,
    NewtonSettings,
    RodState,
    Scene,
    Simulator,
    Sphere,
    check_device,
    check_range,
    fluid_forces,
    paper_finger,
    paper_scene,
    take_grippers,
    without_material_damping,
)
from .physics.solvers.gpu import cuda_module

MODELS = ("planar", "3d")


class _ModelDefault:
    """The default of a :class:`GraspTask` field that depends on the rod model (:data:`MODEL_DEFAULTS`)."""

    def __repr__(self) -> str:
        return "MODEL_DEFAULT"


MODEL_DEFAULT = _ModelDefault()
MODEL_DEFAULTS = {"3d": {"physics_dt": 0.00125, "friction_passes": 4},
                  "planar": {"physics_dt": 0.000625, "friction_passes": 2}}
"""Each rod model's default physics step [s] and cap on friction's re-solves (:class:`GraspTask`), at Newton's
relative tolerance 1e-4: the largest step at which the grasp's outcomes are those of the finest step studied,
0.3125 ms (``benchmarks/outcome_convergence.py``, ``docs/speed_vs_error.md``). On 400 seeds no controller was
tuned on, the success rate, the endings, the peak finger force and the sphere's final place are the finest step's
within sampling error, and per-seed success labels agree with it within 2 points of the chaos floor, under the
graded controller, the shipped policy, the policy trained planar and the ramp, in both models, and in 3-D under
the on–off reactive controller too (planar its labels converge at no step down to 0.3125 ms, its statistics at
every step). A longer step is faster and keeps the statistics (3-D at 2.5 ms: every test passes but the labels,
97.0 % against 97.5 % asked; planar at 1.25 ms the policies' labels miss by two seeds), so ``physics_dt`` is the
setting to trade: ``docs/speed_vs_error.md`` gives each step's errors and speed."""
OBSERVATIONS = ("full", "sensors")
"""What an observation holds: ``"full"``, the fingers' node states and per-node forces with the sensors' readings;
``"sensors"``, only what a real gripper measures or is told (the same size in both rod models)."""


@dataclass(frozen=True)
class RewardWeights:
    """Scale of each reward term (dimensionless). Each term is bounded: the positive ones lie in [0, weight], the
    penalties in [−weight, 0]. The per-step terms sum to at most 2 per action; the two once-per-episode terms
    (``harm`` and ``success``) are as large as ten such steps, so that ending harmed or succeeding outweighs the
    steps a policy spends on the way."""

    reach: float = 0.25
    """Fingers near the object, 1 − tanh(gap/reach_distance) averaged over the fingers, the gap being the
    distance from a finger's nearest node to the object's surface: it guides a policy to close the fingers."""
    contact: float = 0.25
    """Fraction of fingers in compressive contact."""
    hold: float = 1.0
    """Object near the grasp point, 1 − tanh(d/hold_distance); only while every finger touches it."""
    rest: float = 0.5
    """Object at rest relative to the palm, 1 − tanh(|v|/rest_speed); only while every finger touches it."""
    pressure: float = 1.0
    """Penalty for pressing near or above the specimen's fragility limit: with F the largest finger force of the
    control interval (its 50 ms mean, not the sustained force), F_max the limit and c the task's
    ``pressure_onset``, clip((F/F_max − c)/(1 − c), 0, 2)/2: zero up to the onset, half the weight at the limit,
    the full weight from (2 − c) times it. Success forbids only a sustained F > F_max; this warns before it, so
    that a policy learns the margin and not the edge. It reads the interval's force, which the harm rule's filter
    smooths, and keeps growing past the limit, because a policy otherwise learns to squeeze in pulses the filter
    hides: a penalty that is flat above the limit gives no reason to squeeze at 1.2 rather than 2 times it."""
    effort: float = 0.05
    """Penalty mean(action²)."""
    harm: float = 20.0
    """Penalty, once, when a finger presses above the specimen's fragility limit (the episode ends there)."""
    success: float = 20.0
    """Bonus, once, at the episode's last step if it succeeded."""

    def __post_init__(self) -> None:
        for f in fields(self):
            check_range("RewardWeights", f.name, getattr(self, f.name), "(dimensionless)", 0.0, 1e6,
                        low_inclusive=True)


@dataclass(frozen=True)
class GraspTask:
    """Settings of the underwater grasp task (SI units). Ranges are (low, high) and drawn uniformly at reset."""

    model: str = "3d"
    """Rod model of the fingers: ``"planar"`` or ``"3d"``."""
    observation: str = "full"
    """What the observation holds (the env's spec sheet): ``"full"``, every node's position and velocity and the
    per-node contact forces, then the sensors' readings; ``"sensors"``, the readings alone (per finger: κ̄, force,
    gap and touching; the specimen's fragility limit, radius, offset and velocity; the episode fraction), which
    a real gripper has and which do not depend on the rod model, so a policy trained in one model runs in the
    other."""
    gripper: GripperDesign = field(default_factory=lambda: GripperDesign(paper_finger()))
    """The gripper: its fingers (design, count and directions) set the sizes of the action and the observation.
    The paper's three fingers of 20 nodes by default."""
    control_dt: float = 0.05
    """Time between actions [s]; a multiple of ``physics_dt``."""
    physics_dt: float = MODEL_DEFAULT
    """Implicit physics step [s]. By default the rod model's (:data:`MODEL_DEFAULTS`: 1.25 ms in 3-D, 0.625 ms planar),
    set at construction: ``dataclasses.replace(task, model=...)`` keeps the other model's."""
    newton: NewtonSettings = field(default_factory=lambda: NewtonSettings(relative_tolerance=1e-4))
    """Stopping rule of the Newton solve inside each physics step: relative tolerance 1e-4. The simulator's default,
    1e-6, costs more iterations for little agreement with the fine reference: in 3-D at 2.5 ms with friction settled
    97.5 % of the reactive controller's labels against 95.0 % (``docs/speed_vs_error.md``)."""
    friction_passes: int | None = MODEL_DEFAULT
    """The corrector's re-solves per physics step in which a sliding node's moved friction alone solves again
    (:attr:`~.physics.scene.objects.ContactSettings.friction_passes`); None settles friction within the whole
    budget. By default the rod model's (:data:`MODEL_DEFAULTS`: four passes in 3-D, two planar), set at
    construction. Without a cap, about a quarter of a grasp's physics steps spend the corrector's whole budget
    cycling on friction; four passes make a 3-D grasping env step about 1.5× faster and keep the grasp's outcome
    (the reactive controller's labels agree with the fine reference on 95.5 % of seeds), two would be faster still
    but move it (94.0 %; ``docs/speed_vs_error.md``)."""
    max_curvature_rate: float = 0.3
    """Natural-curvature rate of an action of ±1 [1/s] (κ̄ per node at the gripper's 20 nodes per finger): the
    fastest closing. 0.3 1/s is the slowest approach that still catches the drifting specimen (the reactive
    controller closing at 0.2 1/s loses the specimen on 21 of 96 tuning seeds, at 0.15 1/s on 36, at 0.3 1/s on 2);
    a faster one only lets a policy meet the specimen harder (one control interval past the touch at 0.5 1/s adds
    Δκ̄ = 0.025, about 5 N at a grip's 0.2 N per 0.001; docs/environment.md)."""
    action_exponent: float = 3.0
    """An action a in [−1, 1] sets the rate max_curvature_rate·sign(a)·|a|^p, p this exponent (dimensionless,
    ≥ 1): a grip's force follows κ̄ steeply (a κ̄ change of 0.001 presses about 0.2 N harder), so holding a fragile
    specimen needs rates a hundredth of the closing rate's, and with p = 3 they lie at |a| ≈ 0.3 and not 0.04,
    where an exploring policy's noise of a few tenths would crush it."""
    touching_closing_rate: float | None = None
    """The fastest a finger that touches the specimen (:attr:`GraspBatch.touching`, as the observation reads it
    at the start of the control interval) closes [1/s], whatever its action asks; opening is never bounded. None
    (the default): no bound, so the env and its baselines are without it. It is the reactive controller's own rule
    made a reflex of the gripper. ``agents.train_ppo`` trains with 0.15 1/s (and a 1 cm
    :attr:`approach_slowing_gap`): with them PPO holds more gently than the controller and more often
    (docs/training.md). A policy trained with a bound must be run with the same one."""
    approach_slowing_gap: float | None = None
    """Within this gap [m] of the specimen (:attr:`GraspBatch.finger_gap` at the start of the control interval)
    a finger that does not touch closes at most at a rate falling linearly with its gap, from
    ``max_curvature_rate`` at this gap to ``touching_closing_rate`` in contact; needs ``touching_closing_rate``.
    None (the default): no slowing. It is the reactive controller's approach (slowing within 1 cm) made a reflex,
    and the controller acts the same with it. Both reflexes on a policy trained without them trade success for
    force, and PPO trained with them holds tighter unless the reward's pressure warning grows (weight 12 in
    ``agents.train_ppo``; docs/notes/ppo_experiments.md). A policy trained with it must be run with the same gap."""
    curvature_range: tuple[float, float] = (-0.2, 0.0)
    """Range of κ̄ (dimensionless) the actuators reach: κ̄ saturates there, as a pneumatic finger saturates at its
    maximum pressure (−0.2: each finger's natural shape curls through about 205°) and is straight without
    pressure."""
    object_radius: tuple[float, float] = (0.045, 0.06)
    """Radius of the sphere [m]."""
    object_density: tuple[float, float] = (990.0, 1030.0)
    """Density of the sphere [kg/m³]: near-neutrally buoyant, as soft underwater specimens are, within −1 … +3 % of
    the water's. It still drifts: a 1030 kg/m³ sphere sinks 8–10 cm in the first second, so a grasp must form soon."""
    object_friction: float = DEFAULT_FRICTION
    """Coulomb friction coefficient μ between the fingers (and the palm) and the sphere (dimensionless; 0.3, silicone
    on a wet object, ``docs/contact.md``); ``math.inf`` makes every contact stick."""
    grasp_point: tuple[float, float, float] = (0.0, 0.0, -0.09)
    """Where a grasped object should sit, relative to the palm centre [m]: the middle of where the closed fingers
    cage a sphere of the task's sizes, from up against the finger roots (z ≈ −0.07 m) to cradled by the fingertips
    (z ≈ −0.13 m for the largest)."""
    start_point: tuple[float, float, float] = (0.0, 0.0, -0.1)
    """Where the sphere starts, before the offset, relative to the palm centre [m]: below the open fingers (they
    lie straight out in the palm's plane, 0.02 m thick), 1 cm clear of them at the largest radius and offset."""
    object_offset: tuple[float, float, float] = (0.015, 0.015, 0.01)
    """The sphere starts at ``start_point`` plus an offset drawn from ±these per axis [m]."""
    current_speed: tuple[float, float] = (0.0, 0.02)
    """Speed of the mean current, horizontal, in a random direction [m/s]."""
    current_oscillation: tuple[float, float] = (0.0, 0.02)
    """Amplitude of the current's oscillating part, horizontal, in a random direction [m/s]."""
    current_period: tuple[float, float] = (1.0, 3.0)
    """Period of the current's oscillation [s]; its phase is drawn from [0, 2π)."""
    reach_distance: float = 0.05
    """Length scale of the reach term [m]."""
    contact_force: float = 0.01
    """A finger is in compressive contact when the normal reactions on its nodes sum to at least this [N]."""
    fragile_force: tuple[float, float] = (1.0, 4.0)
    """The specimen's fragility limit [N], drawn per episode: the largest force one finger may press on it (the sum
    of the finger's normal reactions, averaged over a control interval) without harming it. Pressing harder harms
    it and ends the episode as a failure. The limit is observed: a gripper is told what it is sent to take."""
    pressure_onset: float = 0.7
    """Fraction of the fragility limit (dimensionless, in [0, 1)) above which the reward's pressure penalty
    grows, reaching half its weight at the limit and its full weight at (2 − onset) times it."""
    sustained_force_time: float = 0.2
    """Time constant [s] of a finger's sustained force: its force, averaged over a control interval, through a
    first-order low-pass filter. The fragility limit bounds it, and a finger touches while it is at least
    ``contact_force``. Soft tissue is harmed by pressure held, not by the brief peaks of a touch or of stick–slip,
    which move a finger's 50 ms mean force by up to ±1 N from one interval to the next and lift a touch for an
    interval now and then; 0 uses the interval mean itself."""
    gust_speed: tuple[float, float] = (0.05, 0.15)
    """Peak speed of the current gust that tests each grasp [m/s], horizontal, in a random direction."""
    gust_start: tuple[float, float] = (2.0, 2.5)
    """When the gust begins [s], drawn per episode."""
    gust_duration: float = 0.5
    """How long the gust blows [s], rising and falling smoothly (:class:`~.physics.Current`)."""
    episode_duration: float = 4.0
    """Length of an episode [s]: the registered environment's time limit is this over ``control_dt`` (80
    actions)."""
    hold_distance: float = 0.05
    """Held: the object's centre within this of the grasp point [m]."""
    rest_speed: float = 0.05
    """Held: the object slower than this relative to the palm [m/s]."""
    success_duration: float = 1.0
    """Success: at the episode's end, held continuously since the gust began and for at least this long [s], and
    never harmed."""
    lost_distance: float = 0.15
    """The episode terminates when the object's centre is farther than this from the grasp point [m]."""
    reward: RewardWeights = field(default_factory=RewardWeights)

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"GraspTask.model = {self.model!r} is not one of 'planar', '3d'")
        for name, value in MODEL_DEFAULTS[self.model].items():
            if getattr(self, name) is MODEL_DEFAULT:
                object.__setattr__(self, name, value)
        if self.observation not in OBSERVATIONS:
            raise ValueError(f"GraspTask.observation = {self.observation!r} is not one of 'full', 'sensors'")
        if not isinstance(self.gripper, GripperDesign):
            raise ValueError(f"GraspTask.gripper must be a GripperDesign, got {type(self.gripper).__name__}")
        check_range("GraspTask", "physics_dt", self.physics_dt, "s", 0.0, 0.05, high_inclusive=True)
        check_range("GraspTask", "control_dt", self.control_dt, "s", 0.0, 1.0)
        substeps = self.control_dt / self.physics_dt
        if substeps < 1.0 - 1e-9 or abs(substeps - round(substeps)) > 1e-6:
            raise ValueError(f"GraspTask.control_dt = {self.control_dt!r} s must be a whole multiple of physics_dt = "
                             f"{self.physics_dt!r} s")
        try:  # the contact settings' own check, naming the task's field
            ContactSettings(friction_passes=self.friction_passes)
        except ValueError as error:
            raise ValueError(str(error).replace("ContactSettings.", "GraspTask.")) from None
        check_range("GraspTask", "max_curvature_rate", self.max_curvature_rate, "1/s", 0.0, 100.0)
        check_range("GraspTask", "action_exponent", self.action_exponent, "(dimensionless)", 1.0, 10.0,
                    low_inclusive=True, high_inclusive=True)
        if self.touching_closing_rate is not None:
            check_range("GraspTask", "touching_closing_rate", self.touching_closing_rate, "1/s", 0.0, 100.0)
        if self.approach_slowing_gap is not None:
            check_range("GraspTask", "approach_slowing_gap", self.approach_slowing_gap, "m", 0.0, 0.1,
                        high_inclusive=True)
            if self.touching_closing_rate is None or self.touching_closing_rate > self.max_curvature_rate:
                raise ValueError(f"GraspTask.approach_slowing_gap = {self.approach_slowing_gap!r} m slows the "
                                 f"approach to GraspTask.touching_closing_rate, which must then be set and at most "
                                 f"GraspTask.max_curvature_rate = {self.max_curvature_rate!r} 1/s (got "
                                 f"{self.touching_closing_rate!r})")
        _check_interval("curvature_range", self.curvature_range, "(dimensionless)", -NATURAL_CURVATURE_LIMIT,
                        NATURAL_CURVATURE_LIMIT)
        if not self.curvature_range[0] <= 0.0 <= self.curvature_range[1]:
            raise ValueError(f"GraspTask.curvature_range = {self.curvature_range!r} must contain 0 (the straight "
                             f"finger every episode starts from)")
        if not (isinstance(self.object_friction, (int, float, np.floating)) and self.object_friction >= 0.0):
            raise ValueError(f"GraspTask.object_friction = {self.object_friction!r} is outside the allowed range "
                             f"[0, inf] (dimensionless)")
        _check_interval("object_radius", self.object_radius, "m", *OPTION_RANGES["object_radius"])
        _check_interval("object_density", self.object_density, "kg/m³", *OPTION_RANGES["object_density"])
        _check_interval("current_speed", self.current_speed, "m/s", 0.0, 0.5)
        _check_interval("current_oscillation", self.current_oscillation, "m/s", 0.0, 0.5)
        _check_interval("current_period", self.current_period, "s", *OPTION_RANGES["current_period"])
        for name, low, high in (("grasp_point", -0.3, 0.3), ("start_point", -0.3, 0.3), ("object_offset", 0.0, 0.05)):
            value = tuple(getattr(self, name))
            if len(value) != 3:
                raise ValueError(f"GraspTask.{name} = {value!r} must have 3 components [m]")
            for v in value:
                check_range("GraspTask", name, v, "m", low, high, low_inclusive=True)
            object.__setattr__(self, name, tuple(float(v) for v in value))
        for name, unit in (("reach_distance", "m"), ("contact_force", "N"), ("hold_distance", "m"),
                           ("rest_speed", "m/s"), ("success_duration", "s"), ("lost_distance", "m"),
                           ("gust_duration", "s"), ("episode_duration", "s")):
            check_range("GraspTask", name, getattr(self, name), unit, 0.0, 1e3)
        check_range("GraspTask", "sustained_force_time", self.sustained_force_time, "s", 0.0, 100.0,
                    low_inclusive=True)
        _check_interval("fragile_force", self.fragile_force, "N", *OPTION_RANGES["fragile_force"])
        check_range("GraspTask", "pressure_onset", self.pressure_onset, "(dimensionless)", 0.0, 1.0,
                    low_inclusive=True)
        _check_interval("gust_speed", self.gust_speed, "m/s", 0.0, 0.5)
        _check_interval("gust_start", self.gust_start, "s", 0.0, 1e3)
        last_gust_end = self.gust_start[1] + self.gust_duration
        if last_gust_end + self.success_duration > self.episode_duration + 1e-9:
            raise ValueError(f"GraspTask.episode_duration = {self.episode_duration!r} s must leave success_duration = "
                             f"{self.success_duration!r} s after the latest gust's end ({last_gust_end!r} s)")
        if abs(self.episode_duration / self.control_dt - round(self.episode_duration / self.control_dt)) > 1e-6:
            raise ValueError(f"GraspTask.episode_duration = {self.episode_duration!r} s must be a whole multiple of "
                             f"control_dt = {self.control_dt!r} s")
        if not isinstance(self.newton, NewtonSettings):
            raise ValueError(f"GraspTask.newton must be a NewtonSettings, got {type(self.newton).__name__}")
        if not isinstance(self.reward, RewardWeights):
            raise ValueError(f"GraspTask.reward must be a RewardWeights, got {type(self.reward).__name__}")

    @property
    def substeps(self) -> int:
        """Physics steps per action."""
        return int(round(self.control_dt / self.physics_dt))

    def curvature_rate(self, action: np.ndarray) -> np.ndarray:
        """The natural-curvature rate [1/s] of actions in [−1, 1] (``action_exponent``)."""
        return self.max_curvature_rate * np.sign(action) * np.abs(action) ** self.action_exponent

    def action_for_rate(self, rate: np.ndarray) -> np.ndarray:
        """The action in [−1, 1] that sets the natural-curvature rate ``rate`` [1/s] (clipped to the range)."""
        ratio = np.clip(np.asarray(rate, dtype=float) / self.max_curvature_rate, -1.0, 1.0)
        return np.sign(ratio) * np.abs(ratio) ** (1.0 / self.action_exponent)

    @property
    def max_episode_steps(self) -> int:
        """Actions per episode."""
        return int(round(self.episode_duration / self.control_dt))


OPTION_RANGES = {
    "object_radius": (0.01, 0.09),
    "object_density": (500.0, 3000.0),
    "current_period": (0.1, 100.0),
    "fragile_force": (0.01, 100.0),
    "gust_start": (0.0, 1e3),
}
_OPTION_UNITS = {"object_radius": "m", "object_density": "kg/m³", "current_period": "s", "fragile_force": "N",
                 "gust_start": "s"}
"""Allowed (low, high) of the scalars that ``reset(options=...)`` may fix, and of the task's drawn ranges."""
VECTOR_OPTIONS = {"object_offset": (0.05, "m"), "current_velocity": (0.5, "m/s"), "current_oscillation": (0.5, "m/s"),
                  "gust_velocity": (0.5, "m/s")}
"""The 3-vectors that ``reset(options=...)`` may fix: each component in [−bound, bound), and its unit."""
SCENE_OPTIONS = ("task", "paper")


def _norms(vectors: np.ndarray) -> np.ndarray:
    """Euclidean norms along the last axis: ``np.linalg.norm(vectors, axis=-1)``'s arithmetic, to the bit, at a
    third of its call's cost (the task takes a few per step)."""
    return np.sqrt(np.add.reduce(vectors * vectors, axis=-1))


def _finger_mean(values: np.ndarray) -> np.ndarray:
    """Mean over the fingers of (B, F) values: ``values.mean(axis=1)``'s arithmetic, to the bit (the sum, in float64
    for bool and integers as ``mean`` takes it, divided by F), without its Python-level wrapper."""
    return np.add.reduce(values, axis=1, dtype=np.float64 if values.dtype.kind in "biu" else None) / values.shape[1]


def _check_interval(name, value, unit, low, high) -> None:
    value = tuple(value)
    if len(value) != 2 or not float(value[0]) <= float(value[1]):
        raise ValueError(f"GraspTask.{name} = {value!r} must be a (low, high) pair with low ≤ high [{unit}]")
    for v in value:
        check_range("GraspTask", name, v, unit, low, high, low_inclusive=True)


def check_options(options: dict | None) -> dict:
    """Validates the options of ``reset``: which keys, and that every value is in its allowed range."""
    options = {} if options is None else options
    if not isinstance(options, dict):
        raise ValueError(f"reset options must be a dict or None, got {type(options).__name__}")
    allowed = {"scene", "current_phase", *OPTION_RANGES, *VECTOR_OPTIONS}
    unknown = set(options) - allowed
    if unknown:
        raise ValueError(f"reset options {sorted(unknown)} are unknown; allowed: {sorted(allowed)}")
    checked = dict(options)
    if options.get("scene", "task") not in SCENE_OPTIONS:
        raise ValueError(f"reset option scene = {options['scene']!r} is not one of 'task', 'paper'")
    for name, (low, high) in OPTION_RANGES.items():
        if name in options:
            check_range("reset option", name, options[name], _OPTION_UNITS[name], low, high, low_inclusive=True)
            checked[name] = float(options[name])
    if "current_phase" in options:
        check_range("reset option", "current_phase", options["current_phase"], "rad", -1e3, 1e3, low_inclusive=True)
    for name, (bound, unit) in VECTOR_OPTIONS.items():
        if name in options:
            try:
                value = np.asarray(options[name], dtype=float)
            except (TypeError, ValueError):
                value = None
            if value is None or value.shape != (3,):
                raise ValueError(f"reset option {name} = {options[name]!r} must have 3 components")
            for v in value:
                check_range("reset option", name, v, unit, -bound, bound, low_inclusive=True)
            checked[name] = tuple(float(v) for v in value)
    return checked


class TaskEpisode(NamedTuple):
    """One episode as drawn at reset: its scene, and what the task knows of the specimen beyond the physics."""

    scene: Scene
    fragile_force: float
    """The specimen's fragility limit [N] (:attr:`GraspTask.fragile_force`)."""


def task_episode(task: GraspTask, rng: np.random.Generator, options: dict) -> TaskEpisode:
    """One episode: its scene and specimen drawn from the task's ranges by ``rng``, with ``options`` (checked)
    fixing any of them; or the paper's exact scene (its fixed ball, Stokes drag, no buoyancy, no gust, nothing
    fragile) for ``scene="paper"``, with the task's gripper (the paper's, unless the task names another), its
    material purely elastic as the paper's."""
    if options.get("scene") == "paper":
        gripper = without_material_damping(task.gripper)
        return TaskEpisode(replace(paper_scene(task.model, grasped_object=PAPER_BALL), gripper=gripper,
                                   time_step=task.physics_dt, newton=task.newton), math.inf)
    # every draw is made, fixed or not, so that fixing one quantity leaves the others' draws unchanged
    radius = rng.uniform(*task.object_radius)
    density = rng.uniform(*task.object_density)
    offset = rng.uniform(-1.0, 1.0, 3) * task.object_offset
    speed, heading = rng.uniform(*task.current_speed), rng.uniform(0.0, 2 * math.pi)
    amplitude, sway = rng.uniform(*task.current_oscillation), rng.uniform(0.0, 2 * math.pi)
    period, phase = rng.uniform(*task.current_period), rng.uniform(0.0, 2 * math.pi)
    fragile_force = rng.uniform(*task.fragile_force)
    gust_speed, gust_heading = rng.uniform(*task.gust_speed), rng.uniform(0.0, 2 * math.pi)
    gust_start = rng.uniform(*task.gust_start)
    offset = options.get("object_offset", offset)
    current = Current(velocity=options.get("current_velocity", (speed * math.cos(heading), speed * math.sin(heading),
                                                                0.0)),
                      oscillation=options.get("current_oscillation", (amplitude * math.cos(sway),
                                                                      amplitude * math.sin(sway), 0.0)),
                      period=options.get("current_period", period), phase=options.get("current_phase", phase),
                      gust_velocity=options.get("gust_velocity", (gust_speed * math.cos(gust_heading),
                                                                  gust_speed * math.sin(gust_heading), 0.0)),
                      gust_start=options.get("gust_start", gust_start), gust_duration=task.gust_duration)
    sphere = Sphere(options.get("object_radius", radius), tuple(np.add(task.start_point, offset)),
                    density=options.get("object_density", density), friction=task.object_friction)
    palm_friction = min(task.object_friction, 1e5)  # the palm's law is regularised and takes a finite μ
    scene = Scene(gripper=task.gripper, forces=(Gravity(),) + fluid_forces("water"), fluid=Fluid(current=current),
                  model=task.model, time_step=task.physics_dt, newton=task.newton, grasped_object=sphere,
                  contact=ContactSettings(palm_friction=palm_friction, friction_passes=task.friction_passes))
    return TaskEpisode(scene, options.get("fragile_force", fragile_force))


@dataclass(frozen=True)
class StepOutcome:
    """What :meth:`GraspBatch.step` returns, per episode (B,)."""

    reward: np.ndarray
    terminated: np.ndarray
    """The object lost, or the specimen harmed."""
    truncated: np.ndarray
    """A solver failure, or the episode's end (``episode_duration``), where not terminated."""
    solver_failure: np.ndarray
    reward_terms: dict[str, np.ndarray]
    """Each reward term (B,); they sum to ``reward``."""


class GraspBatch:
    """B episodes of the grasp task stepped together in one batched simulator, whose physics runs on ``device``
    ("cpu", or "cuda": :class:`~.physics.simulator.Simulator`); the task's own arrays are the host's either way."""

    def __init__(self, task: GraspTask, batch_size: int, device: str = "cpu") -> None:
        self.task = task
        self.batch_size = batch_size
        self.device = check_device(device)
        if self.device == "cuda":
            cuda_module()  # no GPU, or no numba-cuda: say so now, not at the first reset
        self.sim: Simulator | None = None
        self.state: RodState | None = None
        self.kind = None
        B, F = batch_size, task.gripper.n_fingers
        self.natural_curvature = np.zeros((B, F))
        """κ̄ of every finger (dimensionless)."""
        self.normal_force = np.zeros((B, F, task.gripper.finger.n_nodes))
        """Compressive reaction of the object on every node, averaged over the last control interval [N]: stick
        contact makes the reaction of a single physics step impulsive, its mean over the interval is not."""
        self.contact_force = np.zeros((B, F, task.gripper.finger.n_nodes, 3))
        """The object's mean force on each node over the last control interval, normal reaction and friction, world
        frame [N], (B, F, N, 3)."""
        self.hold_time = np.zeros(B)
        """How long each object has been held without a break [s]."""
        self.fragile_force = np.full(B, np.inf)
        """Each specimen's fragility limit [N]."""
        self.gust_start = np.zeros(B)
        """When each episode's gust begins [s] (0 where none blows)."""
        self.gust_end = np.zeros(B)
        """When it has passed [s]."""
        self.has_gust = np.zeros(B, dtype=bool)
        """Whether a gust blows in each episode (not in the paper's scene)."""
        self.sustained_force = np.zeros((B, task.gripper.n_fingers))
        """Each finger's force through the low-pass filter of ``sustained_force_time`` [N], (B, F)."""
        self.harmed = np.zeros(B, dtype=bool)
        """Whether a finger pressed above the specimen's fragility limit (the episode then ends)."""
        self.kept_through_gust = np.ones(B, dtype=bool)
        """Whether every finger touched the object when the gust began, and the object has stayed within
        ``hold_distance`` of the grasp point since."""
        self.object_radius = np.zeros(B)
        """Each object's radius [m]."""
        self.time = np.zeros(B)
        """Simulated time of each episode [s]."""
        self.newton_iterations = np.zeros(B, dtype=np.int64)
        self._gap_of: tuple[RodState | None, np.ndarray | None] = (None, None)
        """:attr:`finger_gap` and the state it was measured in: the task reads it up to three times per step (the
        reflexes, the reward, the observation), and each measure costs about a third of the whole reward's time."""

    # --- reset -----------------------------------------------------------------------------------------------------
    def reset(self, indices, episodes: list[TaskEpisode], kind: str) -> None:
        """Starts new episodes in the slots ``indices`` (one each, :func:`task_episode`). ``kind`` ("task" or
        "paper") must be the same for the whole batch; a change of kind rebuilds the simulator, which needs every
        slot."""
        indices = np.asarray(indices, dtype=np.int64)
        scenes = [episode.scene for episode in episodes]
        if kind != self.kind:
            if len(indices) != self.batch_size:
                raise ValueError(f"reset option scene = {kind!r}: a vector of environments runs one kind of scene; "
                                 f"reset all of them together to change it")
            order = np.argsort(indices)
            self.sim = Simulator([scenes[i] for i in order], device=self.device)
            self.kind = kind
            self.state = self.sim.initial_state()
        elif len(indices) == self.batch_size:
            for index, scene in zip(indices, scenes, strict=True):
                self.sim.set_scene(int(index), scene)
            self.state = self.sim.initial_state()
        else:  # the others run on: the new episodes' clocks start at the batch's present time
            for index, scene in zip(indices, scenes, strict=True):
                self.sim.set_scene(int(index), scene, start_time=self.state.time)
            self.state = self.sim.put_grippers(self.state, indices, take_grippers(self.sim.initial_state(), indices))
        self.natural_curvature[indices] = 0.0
        self.normal_force[indices] = 0.0
        self.contact_force[indices] = 0.0
        self.hold_time[indices] = 0.0
        self.fragile_force[indices] = [episode.fragile_force for episode in episodes]
        currents = [scene.fluid.current for scene in scenes]
        self.gust_start[indices] = [current.gust_start for current in currents]
        self.gust_end[indices] = [current.gust_start + current.gust_duration for current in currents]
        self.has_gust[indices] = [current.has_gust for current in currents]
        self.harmed[indices] = False
        self.sustained_force[indices] = 0.0
        self.kept_through_gust[indices] = True
        self.object_radius[indices] = [scene.grasped_object.radius for scene in scenes]
        self.time[indices] = 0.0
        self.newton_iterations[indices] = 0

    # --- step ------------------------------------------------------------------------------------------------------
    def step(self, action: np.ndarray, active: np.ndarray) -> StepOutcome:
        """Advances the episodes where ``active`` (B,) by one control interval with ``action`` (B, F) in [−1, 1]."""
        task = self.task
        rate = task.curvature_rate(action)
        fastest = self.fastest_closing
        if fastest is not None:  # closing lowers κ̄
            rate = np.maximum(rate, -fastest)
        advanced = self.sim.advance(self.state, self.natural_curvature, rate, task.substeps, task.curvature_range,
                                    running=active, clock=self.time)
        self.state, self.natural_curvature, self.time = advanced.state, advanced.natural_curvature, advanced.clock
        failed = advanced.failed
        self.newton_iterations = np.where(active, advanced.newton_iterations, self.newton_iterations)
        # the active episodes' rows updated in place: ``where=`` costs one call, a masked update three
        np.divide(advanced.normal_impulse, task.control_dt, out=self.normal_force, where=active[:, None, None])
        np.divide(advanced.impulse, task.control_dt, out=self.contact_force, where=active[:, None, None, None])

        decay = math.exp(-task.control_dt / task.sustained_force_time) if task.sustained_force_time > 0 else 0.0
        np.copyto(self.sustained_force, decay * self.sustained_force + (1.0 - decay) * self.finger_force,
                  where=active[:, None])
        harm = active & ~self.harmed & (self.sustained_force.max(axis=1) > self.fragile_force)
        self.harmed |= harm
        grasped = self.touching.all(axis=1)
        distance = _norms(self.object_offset)
        speed = _norms(self.object_velocity)
        near = distance <= task.hold_distance
        held = grasped & near & (speed <= task.rest_speed)
        blowing = active & self.has_gust & (self.time >= self.gust_start - 1e-9)
        began = blowing & (self.time - task.control_dt < self.gust_start - 1e-9)
        self.kept_through_gust &= ~(began & ~grasped) & ~(blowing & ~near)
        self.hold_time = np.where(active, np.where(held, self.hold_time + task.control_dt, 0.0), self.hold_time)
        last = active & (self.time >= task.episode_duration - 1e-9)
        terms = self._reward_terms(action, grasped, distance, speed, harm, last & self.is_success)
        reward = sum(terms.values())
        terminated = active & ((distance > task.lost_distance) | harm)
        return StepOutcome(reward=reward, terminated=terminated, truncated=~terminated & ((active & failed) | last),
                           solver_failure=active & failed, reward_terms=terms)

    # --- what the episodes see -------------------------------------------------------------------------------------
    @property
    def object_position(self) -> np.ndarray:
        """Object centre relative to the palm centre [m], (B, 3)."""
        if self.state.body_position is not None:
            return self.state.body_position
        center = np.asarray(self.sim.scene.grasped_object.center)
        return np.broadcast_to(center, (self.batch_size, 3))

    @property
    def object_offset(self) -> np.ndarray:
        """Object centre relative to the grasp point [m], (B, 3)."""
        return self.object_position - np.asarray(self.task.grasp_point)

    @property
    def object_velocity(self) -> np.ndarray:
        """Object velocity relative to the (fixed) palm [m/s], (B, 3)."""
        if self.state.body_velocity is not None:
            return self.state.body_velocity
        return np.zeros((self.batch_size, 3))

    @property
    def finger_force(self) -> np.ndarray:
        """Sum of the normal reactions on each finger's nodes [N], (B, F)."""
        return self.normal_force.sum(axis=2)

    @property
    def finger_gap(self) -> np.ndarray:
        """Distance from each finger's surface to the object's, at its nearest node [m], (B, F); 0 in contact."""
        state, gap = self._gap_of
        if state is self.state:  # every change of the state makes a new one (step, reset)
            return gap
        nodes = self.sim.world_positions(self.state)  # (B, F, N, 3)
        distance = _norms(nodes - self.object_position[:, None, None, :]) \
            - self.sim.finger_contact_radius
        gap = np.maximum(distance.min(axis=2) - self.object_radius[:, None], 0.0)
        self._gap_of = (self.state, gap)
        return gap

    @property
    def fastest_closing(self) -> np.ndarray | None:
        """The fastest each finger may close in the coming control interval [1/s], (B, F), by the task's reflexes
        (``touching_closing_rate``, ``approach_slowing_gap``); None when it has none."""
        task = self.task
        if task.touching_closing_rate is None:
            return None
        free = task.max_curvature_rate
        if task.approach_slowing_gap is not None:
            nearness = np.minimum(self.finger_gap / task.approach_slowing_gap, 1.0)
            free = task.touching_closing_rate + (task.max_curvature_rate - task.touching_closing_rate) * nearness
        return np.where(self.touching, task.touching_closing_rate, free)

    @property
    def touching(self) -> np.ndarray:
        """Which fingers press on the object with a sustained force (:attr:`sustained_force`) of at least
        ``contact_force``, (B, F) bool: a touch that stick–slip lifts for one control interval still counts."""
        return self.sustained_force >= self.task.contact_force

    @property
    def is_success(self) -> np.ndarray:
        """Never harmed, the gust passed and the object kept through it (every finger touching it when the gust
        began, and never farther than ``hold_distance`` from the grasp point since), and held for at least
        ``success_duration`` without a break, (B,)."""
        return ~self.harmed & (self.time >= self.gust_end - 1e-9) & self.kept_through_gust \
            & (self.hold_time >= self.task.success_duration - 1e-9)

    def _reward_terms(self, action: np.ndarray, grasped: np.ndarray, distance: np.ndarray, speed: np.ndarray,
                      harm: np.ndarray, succeeded: np.ndarray) -> dict[str, np.ndarray]:
        """Each term of :class:`RewardWeights`, (B,), from the step's measures: every finger touching
        (``grasped``), the object's distance from the grasp point [m] and speed [m/s], the harm done in this step
        and whether it ended a successful episode."""
        task, weights = self.task, self.task.reward
        load = self.finger_force.max(axis=1) / self.fragile_force
        return {
            "reach": weights.reach * _finger_mean(1.0 - np.tanh(self.finger_gap / task.reach_distance)),
            "contact": weights.contact * _finger_mean(self.touching),
            "hold": weights.hold * grasped * (1.0 - np.tanh(distance / task.hold_distance)),
            "rest": weights.rest * grasped * (1.0 - np.tanh(speed / task.rest_speed)),
            # np.minimum(np.maximum()) is np.clip's arithmetic at a fifth of its call's cost
            "pressure": -weights.pressure / 2 * np.minimum(np.maximum(
                (load - task.pressure_onset) / (1.0 - task.pressure_onset), 0.0), 2.0),
            "effort": -weights.effort * _finger_mean(action**2),
            "harm": -weights.harm * harm,
            "success": weights.success * succeeded,
        }

    def observation_parts(self) -> dict[str, np.ndarray]:
        """The observation's parts per episode, in the order they are concatenated (see the env's spec sheet)."""
        sim, state = self.sim, self.state
        D = sim.disc.dim
        return {
            "node_positions": state.q[..., :D].reshape(self.batch_size, -1),
            "node_velocities": state.velocity[..., :D].reshape(self.batch_size, -1),
            "natural_curvature": self.natural_curvature,
            "normal_forces": self.normal_force.reshape(self.batch_size, -1),
            "finger_forces": self.finger_force,
            "finger_gaps": self.finger_gap,
            "touching": self.touching.astype(float),
            "fragile_force": np.minimum(self.fragile_force, OPTION_RANGES["fragile_force"][1])[:, None],
            "object_radius": self.object_radius[:, None],
            "object_offset": self.object_offset,
            "object_velocity": self.object_velocity,
            "episode_fraction": (self.time / self.task.episode_duration)[:, None],
        }

