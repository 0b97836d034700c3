"""The underwater grasp task, for a batch of B episodes at once: scenes drawn at reset, actions mapped to natural
curvature, observations, reward terms, success and termination. Pure NumPy over the physics core; the Gymnasium
environments (:mod:`soft_gripper_env.env`) are thin layers over :class:`GraspBatch`, so one environment and any
vector of them run the same code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

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
    check_range,
    fluid_forces,
    paper_finger,
    paper_scene,
    put_grippers,
    take_grippers,
)

MODELS = ("planar", "3d")


@dataclass(frozen=True)
class RewardWeights:
    """Scale of each reward term (dimensionless). Each term is bounded: the positive ones lie in [0, weight], the
    penalties in [−weight, 0]."""

    reach: float = 0.25
    """Fingers near the object, 1 − tanh(gap/reach_distance) averaged over the fingers, the gap being the
    distance from a finger's nearest node to the object's surface: it guides a policy to close the fingers."""
    contact: float = 0.25
    """Fraction of fingers in compressive contact."""
    hold: float = 1.0
    """Object near the grasp point, 1 − tanh(d/hold_distance); only while every finger touches it."""
    rest: float = 0.5
    """Object at rest relative to the palm, 1 − tanh(|v|/rest_speed); only while every finger touches it."""
    overload: float = 1.0
    """Penalty tanh(excess/fragile_force) for the largest finger force above ``fragile_force``."""
    effort: float = 0.05
    """Penalty mean(action²)."""

    def __post_init__(self) -> None:
        for f in fields(self):
            check_range("RewardWeights", f.name, getattr(self, f.name), "(dimensionless)", 0.0, 1e6,
                        low_inclusive=True)


@dataclass(frozen=True)
class GraspTask:
    """Settings of the underwater grasp task (SI units). Ranges are (low, high) and drawn uniformly at reset."""

    model: str = "3d"
    """Rod model of the fingers: ``"planar"`` or ``"3d"``."""
    gripper: GripperDesign = field(default_factory=lambda: GripperDesign(paper_finger()))
    """The gripper: its fingers (design, count and directions) set the sizes of the action and the observation.
    The paper's three fingers of 20 nodes by default."""
    control_dt: float = 0.05
    """Time between actions [s]; a multiple of ``physics_dt``."""
    physics_dt: float = 0.005
    """Implicit physics step [s]. With ``newton``'s and ``friction_passes``' defaults, the cheapest setting measured
    whose grasp outcomes agree with a fine 3-D reference (Δt = 2.5 ms, tolerance 1e-9) under the scripted
    controllers: success labels on ≥ 96.5 % of 200 seeds, final object positions a median ≤ 2.8 mm apart
    (``docs/speed_vs_error.md``). Δt = 0.01 s agrees on only 90 %."""
    newton: NewtonSettings = field(default_factory=lambda: NewtonSettings(relative_tolerance=1e-4))
    """Stopping rule of the Newton solve inside each physics step: relative tolerance 1e-4 (the simulator's default,
    1e-6, changes no grasp outcome measurably and costs more iterations)."""
    friction_passes: int | None = 2
    """The corrector's re-solves per physics step in which a sliding node's moved friction alone solves again
    (:attr:`~.physics.scene.objects.ContactSettings.friction_passes`); None settles friction within the whole
    budget. Two passes make a grasping 3-D env step about 1.4× faster (a quarter of its physics steps otherwise
    spend the corrector's whole budget cycling on friction), and the grasp outcomes still agree with the fine
    reference's on 96.5–97.5 % of 200 seeds, 1.9–2.8 mm apart (``docs/speed_vs_error.md``)."""
    max_curvature_rate: float = 0.5
    """Natural-curvature rate of an action of ±1 [1/s] (κ̄ per node at the gripper's 20 nodes per finger)."""
    curvature_range: tuple[float, float] = (-0.2, 0.0)
    """Range of κ̄ (dimensionless) the actuators reach: κ̄ saturates there, as a pneumatic finger saturates at its
    maximum pressure (−0.2: each finger's natural shape curls through about 205°) and is straight without
    pressure."""
    object_radius: tuple[float, float] = (0.04, 0.06)
    """Radius of the sphere [m]."""
    object_density: tuple[float, float] = (990.0, 1030.0)
    """Density of the sphere [kg/m³]: near-neutrally buoyant, as soft underwater specimens are, within −1 … +3 % of
    the water's. It still drifts: a 1030 kg/m³ sphere sinks 8–10 cm in the first second, so a grasp must form soon."""
    object_friction: float = DEFAULT_FRICTION
    """Coulomb friction coefficient μ between the fingers (and the palm) and the sphere (dimensionless; 0.3, silicone
    on a wet object, ``docs/contact.md``); ``math.inf`` makes every contact stick."""
    grasp_point: tuple[float, float, float] = (0.0, 0.0, -0.1)
    """Where a grasped object should sit, relative to the palm centre [m]."""
    object_offset: tuple[float, float, float] = (0.015, 0.015, 0.01)
    """The sphere starts at the grasp point plus an offset drawn from ±these per axis [m]."""
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
    fragile_force: float = 0.5
    """Largest force one finger may press on the object without harming it [N]."""
    hold_distance: float = 0.03
    """Held: the object's centre within this of the grasp point [m]."""
    rest_speed: float = 0.05
    """Held: the object slower than this relative to the palm [m/s]."""
    success_duration: float = 1.0
    """Success: held continuously for this long [s]."""
    lost_distance: float = 0.15
    """The episode terminates when the object's centre is farther than this from the grasp point [m]."""
    reward: RewardWeights = field(default_factory=RewardWeights)

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"GraspTask.model = {self.model!r} is not one of 'planar', '3d'")
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
        for name, low, high in (("grasp_point", -0.3, 0.3), ("object_offset", 0.0, 0.05)):
            value = tuple(getattr(self, name))
            if len(value) != 3:
                raise ValueError(f"GraspTask.{name} = {value!r} must have 3 components [m]")
            for v in value:
                check_range("GraspTask", name, v, "m", low, high, low_inclusive=True)
            object.__setattr__(self, name, tuple(float(v) for v in value))
        for name, unit in (("reach_distance", "m"), ("contact_force", "N"), ("fragile_force", "N"),
                           ("hold_distance", "m"), ("rest_speed", "m/s"), ("success_duration", "s"),
                           ("lost_distance", "m")):
            check_range("GraspTask", name, getattr(self, name), unit, 0.0, 1e3)
        if not isinstance(self.newton, NewtonSettings):
            raise ValueError(f"GraspTask.newton must be a NewtonSettings, got {type(self.newton).__name__}")
        if not isinstance(self.reward, RewardWeights):
            raise ValueError(f"GraspTask.reward must be a RewardWeights, got {type(self.reward).__name__}")

    @property
    def substeps(self) -> int:
        """Physics steps per action."""
        return int(round(self.control_dt / self.physics_dt))


OPTION_RANGES = {
    "object_radius": (0.01, 0.09),
    "object_density": (500.0, 3000.0),
    "current_period": (0.1, 100.0),
}
_OPTION_UNITS = {"object_radius": "m", "object_density": "kg/m³", "current_period": "s"}
"""Allowed (low, high) of the scalars that ``reset(options=...)`` may fix, and of the task's drawn ranges."""
VECTOR_OPTIONS = {"object_offset": (0.05, "m"), "current_velocity": (0.5, "m/s"), "current_oscillation": (0.5, "m/s")}
"""The 3-vectors that ``reset(options=...)`` may fix: each component in [−bound, bound), and its unit."""
SCENE_OPTIONS = ("task", "paper")


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


def task_scene(task: GraspTask, rng: np.random.Generator, options: dict) -> Scene:
    """The scene of one episode: drawn from the task's ranges by ``rng``, with ``options`` (checked) fixing any of
    them; or the paper's exact scene (its fixed ball, Stokes drag, no buoyancy) for ``scene="paper"``, with the
    task's gripper (the paper's, unless the task names another)."""
    if options.get("scene") == "paper":
        return replace(paper_scene(task.model, grasped_object=PAPER_BALL), gripper=task.gripper,
                       time_step=task.physics_dt, newton=task.newton)
    # every draw is made, fixed or not, so that fixing one quantity leaves the others' draws unchanged
    radius = rng.uniform(*task.object_radius)
    density = rng.uniform(*task.object_density)
    offset = rng.uniform(-1.0, 1.0, 3) * task.object_offset
    speed, heading = rng.uniform(*task.current_speed), rng.uniform(0.0, 2 * math.pi)
    amplitude, sway = rng.uniform(*task.current_oscillation), rng.uniform(0.0, 2 * math.pi)
    period, phase = rng.uniform(*task.current_period), rng.uniform(0.0, 2 * math.pi)
    offset = options.get("object_offset", offset)
    current = Current(velocity=options.get("current_velocity", (speed * math.cos(heading), speed * math.sin(heading),
                                                                0.0)),
                      oscillation=options.get("current_oscillation", (amplitude * math.cos(sway),
                                                                      amplitude * math.sin(sway), 0.0)),
                      period=options.get("current_period", period), phase=options.get("current_phase", phase))
    sphere = Sphere(options.get("object_radius", radius), tuple(np.add(task.grasp_point, offset)),
                    density=options.get("object_density", density), friction=task.object_friction)
    palm_friction = min(task.object_friction, 1e5)  # the palm's law is regularised and takes a finite μ
    return Scene(gripper=task.gripper, forces=(Gravity(),) + fluid_forces("water"), fluid=Fluid(current=current),
                 model=task.model, time_step=task.physics_dt, newton=task.newton, grasped_object=sphere,
                 contact=ContactSettings(palm_friction=palm_friction, friction_passes=task.friction_passes))


@dataclass(frozen=True)
class StepOutcome:
    """What :meth:`GraspBatch.step` returns, per episode (B,)."""

    reward: np.ndarray
    terminated: np.ndarray
    solver_failure: np.ndarray
    reward_terms: dict[str, np.ndarray]
    """Each reward term (B,); they sum to ``reward``."""


class GraspBatch:
    """B episodes of the grasp task stepped together in one batched simulator."""

    def __init__(self, task: GraspTask, batch_size: int) -> None:
        self.task = task
        self.batch_size = batch_size
        self.sim: Simulator | None = None
        self.state: RodState | None = None
        self.kind = None
        B, F = batch_size, task.gripper.n_fingers
        self.natural_curvature = np.zeros((B, F))
        """κ̄ of every finger (dimensionless)."""
        self.normal_force = np.zeros((B, F, task.gripper.finger.n_nodes))
        self.contact_force = np.zeros((B, F, task.gripper.finger.n_nodes, 3))
        """The object's mean force on each node over the last control interval, normal reaction and friction, world
        frame [N], (B, F, N, 3)."""
        """Compressive reaction of the object on every node, averaged over the last control interval [N]: stick
        contact makes the reaction of a single physics step impulsive, its mean over the interval is not."""
        self.hold_time = np.zeros(B)
        """How long each object has been held without a break [s]."""
        self.time = np.zeros(B)
        """Simulated time of each episode [s]."""
        self.newton_iterations = np.zeros(B, dtype=np.int64)

    # --- reset -----------------------------------------------------------------------------------------------------
    def reset(self, indices, scenes: list[Scene], kind: str) -> None:
        """Starts new episodes in the slots ``indices`` with ``scenes`` (one each). ``kind`` ("task" or "paper")
        must be the same for the whole batch; a change of kind rebuilds the simulator, which needs every slot."""
        indices = np.asarray(indices, dtype=np.int64)
        if kind != self.kind:
            if len(indices) != self.batch_size:
                raise ValueError(f"reset option scene = {kind!r}: a vector of environments runs one kind of scene; "
                                 f"reset all of them together to change it")
            order = np.argsort(indices)
            self.sim = Simulator([scenes[i] for i in order])
            self.kind = kind
            self.state = self.sim.initial_state()
        elif len(indices) == self.batch_size:
            for index, scene in zip(indices, scenes, strict=True):
                self.sim.set_scene(int(index), scene)
            self.state = self.sim.initial_state()
        else:  # the others run on: the new episodes' clocks start at the batch's present time
            for index, scene in zip(indices, scenes, strict=True):
                self.sim.set_scene(int(index), scene, start_time=self.state.time)
            fresh = take_grippers(self.sim.initial_state(), indices)
            if self.state.acceleration is not None:  # zero: the same Newton start as a fresh state's None
                fresh = replace(fresh, acceleration=np.zeros_like(fresh.q))
            self.state = put_grippers(self.state, indices, fresh)
        self.natural_curvature[indices] = 0.0
        self.normal_force[indices] = 0.0
        self.contact_force[indices] = 0.0
        self.hold_time[indices] = 0.0
        self.time[indices] = 0.0
        self.newton_iterations[indices] = 0

    # --- step ------------------------------------------------------------------------------------------------------
    def step(self, action: np.ndarray, active: np.ndarray) -> StepOutcome:
        """Advances the episodes where ``active`` (B,) by one control interval with ``action`` (B, F) in [−1, 1]."""
        task = self.task
        rate = action * task.max_curvature_rate
        low, high = task.curvature_range
        failed = np.zeros(self.batch_size, dtype=bool)
        iterations = np.zeros(self.batch_size, dtype=np.int64)
        running = active.copy()
        impulse = np.zeros_like(self.normal_force)  # Σ normal reaction · Δt over the interval [N·s]
        force_impulse = np.zeros_like(self.contact_force)  # Σ reaction · Δt [N·s]
        for _ in range(task.substeps):
            if not running.any():
                break
            result = self.sim.step(self.state, self.natural_curvature)
            ok = result.converged & _finite(result.state)
            failed |= running & ~ok
            keep = running & ok
            contact = result.contact
            every = keep.all()  # the common case needs no masks
            if every:
                self.state = result.state
            else:  # the batch's clock runs on for all
                index = np.nonzero(keep)[0]
                self.state = replace(put_grippers(self.state, index, take_grippers(result.state, index)),
                                     time=result.state.time)
            step = task.physics_dt if every else np.where(keep, task.physics_dt, 0.0)  # each episode's advance [s]
            if contact is not None:
                normal, reaction = np.maximum(contact.normal_reaction, 0.0), contact.reaction
                if not every:  # a failed episode's reactions may be NaN: masked, not multiplied
                    normal = np.where(keep[:, None, None], normal, 0.0)
                    reaction = np.where(keep[:, None, None, None], reaction, 0.0)
                impulse += normal * task.physics_dt
                force_impulse += reaction * task.physics_dt
            iterations += result.newton_iterations if every else np.where(keep, result.newton_iterations, 0)
            self.natural_curvature = np.clip(self.natural_curvature + rate * np.reshape(step, (-1, 1)), low, high)
            self.time += step
            running = keep
        self.newton_iterations = np.where(active, iterations, self.newton_iterations)
        self.normal_force[active] = impulse[active] / task.control_dt
        self.contact_force[active] = force_impulse[active] / task.control_dt

        terms, held = self._reward_terms(action)
        self.hold_time = np.where(active, np.where(held, self.hold_time + task.control_dt, 0.0), self.hold_time)
        reward = sum(terms.values())
        distance = np.linalg.norm(self.object_position - np.asarray(task.grasp_point), axis=1)
        return StepOutcome(reward=reward, terminated=active & (distance > task.lost_distance),
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
        nodes = self.sim.world_positions(self.state)  # (B, F, N, 3)
        radius = np.array([scene.grasped_object.radius for scene in self.sim.scenes])
        distance = np.linalg.norm(nodes - self.object_position[:, None, None, :], axis=-1) \
            - self.sim.finger_contact_radius
        return np.maximum(distance.min(axis=2) - radius[:, None], 0.0)

    @property
    def is_success(self) -> np.ndarray:
        """Held for at least ``success_duration`` without a break, (B,)."""
        return self.hold_time >= self.task.success_duration - 1e-9

    def _reward_terms(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        task, weights = self.task, self.task.reward
        touching = self.finger_force >= task.contact_force
        grasped = touching.all(axis=1)
        distance = np.linalg.norm(self.object_position - np.asarray(task.grasp_point), axis=1)
        speed = np.linalg.norm(self.object_velocity, axis=1)
        excess = np.maximum(self.finger_force.max(axis=1) - task.fragile_force, 0.0)
        terms = {
            "reach": weights.reach * (1.0 - np.tanh(self.finger_gap / task.reach_distance)).mean(axis=1),
            "contact": weights.contact * touching.mean(axis=1),
            "hold": weights.hold * grasped * (1.0 - np.tanh(distance / task.hold_distance)),
            "rest": weights.rest * grasped * (1.0 - np.tanh(speed / task.rest_speed)),
            "overload": -weights.overload * np.tanh(excess / task.fragile_force),
            "effort": -weights.effort * np.mean(action**2, axis=1),
        }
        held = grasped & (distance <= task.hold_distance) & (speed <= task.rest_speed)
        return terms, held

    def observation_parts(self) -> dict[str, np.ndarray]:
        """The observation's parts per episode, in the order they are concatenated (see the env's spec sheet)."""
        sim, state = self.sim, self.state
        D = sim.disc.dim
        return {
            "node_positions": state.q[..., :D].reshape(self.batch_size, -1),
            "node_velocities": state.velocity[..., :D].reshape(self.batch_size, -1),
            "natural_curvature": self.natural_curvature,
            "normal_forces": self.normal_force.reshape(self.batch_size, -1),
            "object_position": self.object_position,
            "object_velocity": self.object_velocity,
        }


def _finite(state: RodState) -> np.ndarray:
    """Per gripper, whether every coordinate and the body's state are finite (B,)."""
    ok = np.isfinite(state.q).all(axis=(1, 2, 3)) & np.isfinite(state.velocity).all(axis=(1, 2, 3))
    if state.body_position is not None:
        ok &= np.isfinite(state.body_position).all(axis=1) & np.isfinite(state.body_velocity).all(axis=1)
    return ok
