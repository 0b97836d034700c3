"""Gymnasium environments of the underwater grasp: one (:class:`SoftGripperUnderwaterEnv`) and a batched vector
(:class:`SoftGripperUnderwaterVectorEnv`, for ``gym.make_vec``). Both are thin layers over
:class:`~soft_gripper_env.grasp_task.GraspBatch`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields, replace
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .grasp_task import OPTION_RANGES, GraspBatch, GraspTask, RewardWeights, check_options, task_episode
from .physics import check_device

DEFAULT_MAX_EPISODE_STEPS = GraspTask().max_episode_steps
"""Episode length of the registered environment: the default task's 4 s, 80 actions of 0.05 s."""
_POSITION_BOUND = 0.5  # [m]; no node of a 0.2 m finger clamped at the palm gets farther
_VELOCITY_BOUND = 10.0  # [m/s]
_FORCE_BOUND = 100.0  # [N]
_OBJECT_BOUND = 1.0  # [m]


_NODE_PARTS = ("node_positions", "node_velocities", "normal_forces")
"""The parts of a ``"full"`` observation that a ``"sensors"`` observation leaves out."""


def _part_bounds(task: GraspTask) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every part's (low, high) bounds, in the order of the ``"full"`` observation (the env's spec sheet); the
    sizes follow the task's gripper and rod model."""
    dim = 2 if task.model == "planar" else 3
    n_fingers, n_nodes = task.gripper.n_fingers, task.gripper.finger.n_nodes
    nodes, fingers = n_fingers * n_nodes * dim, np.ones(n_fingers)
    return {
        "node_positions": (np.full(nodes, -_POSITION_BOUND), np.full(nodes, _POSITION_BOUND)),
        "node_velocities": (np.full(nodes, -_VELOCITY_BOUND), np.full(nodes, _VELOCITY_BOUND)),
        "natural_curvature": (task.curvature_range[0] * fingers, task.curvature_range[1] * fingers),
        "normal_forces": (np.zeros(n_fingers * n_nodes), np.full(n_fingers * n_nodes, _FORCE_BOUND)),
        "finger_forces": (0 * fingers, _FORCE_BOUND * fingers),
        "finger_gaps": (0 * fingers, _OBJECT_BOUND * fingers),
        "touching": (0 * fingers, fingers),
        "fragile_force": (np.array([OPTION_RANGES["fragile_force"][0]]), np.array([OPTION_RANGES["fragile_force"][1]])),
        "object_radius": (np.array([OPTION_RANGES["object_radius"][0]]), np.array([OPTION_RANGES["object_radius"][1]])),
        "object_offset": (np.full(3, -_OBJECT_BOUND), np.full(3, _OBJECT_BOUND)),
        "object_velocity": (np.full(3, -_VELOCITY_BOUND), np.full(3, _VELOCITY_BOUND)),
        "episode_fraction": (np.zeros(1), np.ones(1)),
    }


def _observed(task: GraspTask, names):
    """Those of ``names`` (in the full observation's order) that an observation of ``task`` holds."""
    return tuple(n for n in names if task.observation == "full" or n not in _NODE_PARTS)


def observed_parts(task: GraspTask) -> tuple[str, ...]:
    """The names of the parts an observation holds, in order (``GraspTask.observation``)."""
    return _observed(task, _part_bounds(task))


def observation_slices(task: GraspTask) -> dict[str, slice]:
    """Where each part of the observation lies (see the env's spec sheet); the sizes follow the task's gripper,
    and the parts its ``observation`` setting."""
    bounds = _part_bounds(task)
    sizes = {name: len(bounds[name][0]) for name in observed_parts(task)}
    ends = np.cumsum(list(sizes.values()))
    return {name: slice(int(end - size), int(end)) for (name, size), end in zip(sizes.items(), ends, strict=True)}


def observation_bounds(task: GraspTask) -> tuple[np.ndarray, np.ndarray]:
    """The observation's low and high bounds (float32), part by part as in the spec sheet."""
    bounds = _part_bounds(task)
    names = observed_parts(task)
    return tuple(np.concatenate([bounds[name][k] for name in names]).astype(np.float32) for k in (0, 1))


def _observations(batch: GraspBatch, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(B, obs_dim) float32, a new array, clipped to the space (only a failing solver could leave it)."""
    parts = batch.observation_parts()  # in the full observation's order; the bounds are not rebuilt every step
    values = np.concatenate([parts[name] for name in _observed(batch.task, parts)], axis=1)
    nan = np.isnan(values)
    if nan.any():  # NaN becomes 0 (the bounds below clip ±inf); testing first costs a tenth of np.nan_to_num
        values[nan] = 0.0
    return np.minimum(np.maximum(values, low, out=values), high, out=values).astype(np.float32)


def _check_actions(action, shape: tuple[int, ...]) -> np.ndarray:
    """The actions as float64 clipped to [−1, 1]; ValueError for a wrong shape or a value that is not finite."""
    try:
        array = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"action {action!r} is not numeric; expected shape {shape} in [-1, 1]") from None
    if array.shape != shape:
        raise ValueError(f"action has shape {array.shape}; expected {shape} in [-1, 1]")
    if not np.isfinite(array).all():
        raise ValueError(f"action {array.tolist()} must be finite (no NaN or inf); allowed range [-1, 1]")
    return np.minimum(np.maximum(array, -1.0), 1.0)  # np.clip's arithmetic at a fraction of its call's cost


def _infos(batch: GraspBatch, terms: dict[str, np.ndarray], failure: np.ndarray) -> dict[str, Any]:
    """The per-episode diagnostics, (B,) arrays (the vector env's layout; the single env takes index 0)."""
    return {
        "reward_terms": terms,
        "is_success": batch.is_success.copy(),
        "harmed": batch.harmed.copy(),
        "fragile_force_N": batch.fragile_force.copy(),
        "solver_failure": failure.copy(),
        "hold_time_s": batch.hold_time.copy(),
        "finger_forces_N": batch.finger_force.copy(),
        "natural_curvature": batch.natural_curvature.copy(),
        "newton_iterations": batch.newton_iterations.copy(),
        "time_s": batch.time.copy(),
    }


def _zero_terms(batch_size: int) -> dict[str, np.ndarray]:
    return {term.name: np.zeros(batch_size) for term in fields(RewardWeights)}


class SoftGripperUnderwaterEnv(gym.Env):
    """Three soft pneumatic fingers take a delicate, near-neutrally buoyant specimen (a sphere) in moving water
    without harming it, and hold it through a gust.

    The fingers are discrete elastic rods (the paper's gripper: L = 0.2 m, r = 0.02 m, 20 nodes, Elastosil) in water
    (Morison drag, added mass, buoyancy), stepped implicitly every ``physics_dt``. The specimen is a free rigid body
    under gravity, buoyancy, drag and added mass, coupled implicitly to the fingers by contact with Coulomb friction.
    Settings are the fields of :class:`~soft_gripper_env.grasp_task.GraspTask`, as keyword arguments:
    ``gym.make("SoftGripperUnderwater-v0", model="planar", control_dt=0.1)``.

    **Action** ``Box(-1, 1, (F,), float32)``, F = 3 fingers for the paper's gripper (``GraspTask.gripper``)

    ======  ===========================================================================  =====
    index   meaning                                                                      unit
    ======  ===========================================================================  =====
    0–F−1   natural-curvature rate of finger k: ``max_curvature_rate`` (0.3 1/s) ×         1/s
            sign(a)·|a|³ (``action_exponent``); negative closes the finger
    ======  ===========================================================================  =====

    The cubic map gives fine rates near zero, where a grip is held (a κ̄ change of 0.001 presses about 0.2 N
    harder), and fast closing at |a| near 1. κ̄ is integrated every physics step and saturates at
    ``curvature_range`` (−0.2 to 0: the maximum pressure, which curls a finger's natural shape through about 205°,
    and no pressure). With ``touching_closing_rate`` set (default None: no bound), a finger that touches the specimen
    at the start of the interval closes no faster than that [1/s], and with ``approach_slowing_gap`` [m] as well, a
    finger within that gap closes no faster than a rate falling linearly with its gap to that bound. Finite values
    outside [−1, 1] are clipped. NaN, inf, a wrong shape or a non-numeric action raise ``ValueError``.

    **Observation** ``Box(float32)``, in this order (F fingers of N nodes, 3 and 20 for the paper's gripper; D = 2
    for the planar model, where positions are (s, z) in each finger's vertical plane, s along the finger's direction
    from the palm centre; D = 3 in 3-D, world (x, y, z)):

    ================  ==========  ===================================================  ======  ===============
    part              size        meaning                                              unit    bounds
    ================  ==========  ===================================================  ======  ===============
    node positions    F·N·D       every node of every finger                           m       ±0.5
    node velocities   F·N·D       their velocities                                     m/s     ±10
    κ̄                F           present natural curvature per finger                 1       curvature_range
    normal forces     F·N         compressive reaction of the specimen on each node,   N       0 … 100
                                  mean over the last control interval
    finger forces     F           their sum per finger                                 N       0 … 100
    finger gaps       F           distance from each finger's surface to the           m       0 … 1
                                  specimen's, at its nearest node (proximity sensing)
    touching          F           1 where a finger's sustained force is at least       1       0 … 1
                                  ``contact_force``
    fragility limit   1           the specimen's limit (a gripper is told what it is   N       0.01 … 100
                                  sent to take)
    specimen radius   1           (seen by the gripper's camera)                       m       0.01 … 0.09
    specimen offset   3           its centre relative to the grasp point (world)       m       ±1
    specimen velocity 3           relative to the palm (world)                         m/s     ±10
    episode fraction  1           elapsed time over ``episode_duration``               1       0 … 1
    ================  ==========  ===================================================  ======  ===============

    Values are clipped to the bounds, which only a failing solve could reach. With ``observation="sensors"``
    (:attr:`~soft_gripper_env.grasp_task.GraspTask.observation`) the node positions, node velocities and normal
    forces are left out: what remains (4F + 9 values, 21 for the paper's gripper) is what a real gripper measures or
    is told, and it has the same size and meaning in both rod models, so a policy trained in one runs in the other.

    **Episode.** Each reset draws (by ``self.np_random``) the specimen's radius (0.045–0.06 m), density (990–1030
    kg/m³), fragility limit (1–4 N) and start (``start_point`` (0.0, 0.0, −0.1) m ± (0.015, 0.015, 0.01) m, below
    the open fingers); a horizontal current (mean 0–0.02 m/s and an oscillation of 0–0.02 m/s with a period of 1–3 s, in
    random directions and phase); and a gust, a smooth horizontal pulse of 0.05–0.15 m/s peak in a random direction
    that begins between 2 and 2.5 s and lasts 0.5 s. ``reset(options=...)`` fixes any of them: ``object_radius``
    [m], ``object_density`` [kg/m³], ``fragile_force`` [N], ``object_offset`` (3,) [m], ``current_velocity`` (3,)
    and ``current_oscillation`` (3,) [m/s], ``current_period`` [s], ``current_phase`` [rad], ``gust_velocity``
    (3,) [m/s] and ``gust_start`` [s]; and ``scene="paper"`` gives the paper's exact scene (its fixed ball, Stokes
    drag, no buoyancy, no gust, nothing fragile) for validation. An unknown key or a value out of its range raises
    ``ValueError``.

    * **Held**: every finger touching (a sustained force of at least ``contact_force``, 0.01 N: the finger's force
      through a low-pass filter of 0.2 s, ``sustained_force_time``), the specimen's centre within 0.05 m of the
      grasp point (0.0, 0.0, −0.09) and slower than 0.05 m/s. ``info["is_success"]``: never harmed; every finger
      touching when the gust began and the specimen within ``hold_distance`` of the grasp point from then on; the
      gust passed; and held for the last 1 s without a break. SB3 reads it at the episode's end.
    * ``terminated``: the specimen is harmed (a finger's sustained force above its fragility limit;
      ``info["harmed"]``) or lost (more than 0.15 m from the grasp point).
    * ``truncated``: the episode's end (``episode_duration`` = 4 s, 80 actions; also the registered time limit), or
      a physics step whose Newton solve failed even after halving (``info["solver_failure"] = True``; the state is
      the last good one, so observations are never NaN). A solver failure is neither the policy's success nor its
      fault, so it truncates rather than terminates.

    **Reward** (weights in :class:`~soft_gripper_env.grasp_task.RewardWeights`; every term is in
    ``info["reward_terms"]``, and they sum to the reward). Per step:

    ========  ===========================================================================  =============
    term      value                                                                        range
    ========  ===========================================================================  =============
    reach     0.25 × mean over fingers of 1 − tanh(gap / 0.05 m)                           [0, 0.25]
    contact   0.25 × fraction of fingers touching                                          [0, 0.25]
    hold      1.0 × (1 − tanh(d / 0.05 m)), d the distance to the grasp point; only while  [0, 1]
              every finger touches
    rest      0.5 × (1 − tanh(|v| / 0.05 m/s)); only while every finger touches             [0, 0.5]
    pressure  −0.5 × clip((F/F_max − 0.7)/0.3, 0, 2), F the largest finger force of the   [−1, 0]
              interval (50 ms mean), F_max the fragility limit: a warning from 70 % of
              the limit that keeps growing to 1.3 times it
    effort    −0.05 × mean(action²)                                                        [−0.05, 0]
    ========  ===========================================================================  =============

    Once: ``harm`` −20 at the step that harms the specimen (the episode ends there), ``success`` +20 at the last
    step of a successful episode. Every penalty is for something success forbids or warns of it.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 20}

    def __init__(self, render_mode: str | None = None, **settings) -> None:
        self.task = GraspTask(**settings)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode = {render_mode!r} is not one of None, 'rgb_array', 'human'")
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.task.control_dt}
        self.action_space = spaces.Box(-1.0, 1.0, (self.task.gripper.n_fingers,), np.float32)
        self._low, self._high = observation_bounds(self.task)
        self.observation_space = spaces.Box(self._low, self._high, dtype=np.float32)
        self._batch = GraspBatch(self.task, 1)
        self._renderer = None
        self._window = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = check_options(options)
        self._batch.reset([0], [task_episode(self.task, self.np_random, options)], options.get("scene", "task"))
        info = _single(_infos(self._batch, _zero_terms(1), np.zeros(1, dtype=bool)))
        if self.render_mode == "human":
            self.render()
        return _observations(self._batch, self._low, self._high)[0], info

    def step(self, action):
        if self._batch.sim is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        action = _check_actions(action, self.action_space.shape)
        outcome = self._batch.step(action[None, :], np.ones(1, dtype=bool))
        info = _single(_infos(self._batch, outcome.reward_terms, outcome.solver_failure))
        if self.render_mode == "human":
            self.render()
        return (_observations(self._batch, self._low, self._high)[0], float(outcome.reward[0]),
                bool(outcome.terminated[0]), bool(outcome.truncated[0]), info)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; make the env with render_mode='rgb_array'")
            return None
        if self._batch.sim is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        if self._renderer is None:
            from .rendering import FrameRenderer

            self._renderer = FrameRenderer()
        batch = self._batch
        frame = self._renderer.draw(batch.sim.world_positions(batch.state)[0], batch.sim.disc.node_radius,
                                    batch.object_position[0], batch.sim.scenes[0].grasped_object.radius,
                                    batch.contact_force[0], float(batch.time[0]), batch.natural_curvature[0])
        if self.render_mode == "rgb_array":
            return frame
        self._show(frame)
        return None

    def _show(self, frame: np.ndarray) -> None:
        import matplotlib.pyplot as plt

        if self._window is None:
            plt.ion()
            figure, axes = plt.subplots(figsize=(frame.shape[1] / 100, frame.shape[0] / 100))
            axes.set_axis_off()
            self._window = (figure, axes.imshow(frame))
        self._window[1].set_data(frame)
        plt.pause(1.0 / self.metadata["render_fps"])

    def close(self) -> None:
        if self._window is not None:
            import matplotlib.pyplot as plt

            plt.close(self._window[0])
            self._window = None


def _single(infos: dict[str, Any]) -> dict[str, Any]:
    """The single env's info: Python scalars, per-finger arrays."""
    out = {}
    for key, value in infos.items():
        if isinstance(value, dict):
            out[key] = {name: float(v[0]) for name, v in value.items()}
        elif value.ndim > 1:
            out[key] = value[0].copy()
        elif value.dtype == bool:
            out[key] = bool(value[0])
        elif value.dtype.kind == "i":
            out[key] = int(value[0])
        else:
            out[key] = float(value[0])
    return out


class SoftGripperUnderwaterVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`SoftGripperUnderwaterEnv` stepped in one batched simulator, or in
    ``num_threads`` of them on as many threads.

    Seeding, options, spaces, rewards and infos are those of the single env (infos as (num_envs,) arrays, with the
    usual ``"_key"`` masks). Env i of ``reset(seed=s)`` is seeded with s + i, as Gymnasium's ``SyncVectorEnv``
    seeds its envs, so the results equal those of ``num_envs`` single envs to rounding. Autoreset follows
    Gymnasium 1.x's default, ``AutoresetMode.NEXT_STEP``: the step after an episode ends resets that env, ignores
    its action, and returns its first observation with reward 0. The paper's scene (``scene="paper"``) is for the
    single env only.

    ``num_threads`` > 1 splits the envs into that many consecutive shards, each a batched simulator of its own,
    and steps them on a thread each. The compiled physics releases Python's lock, so the shards' physics runs on
    separate cores while one shard's Python bookkeeping overlaps the other's physics. Every env's results are those
    of one thread: a shard steps its envs exactly as the whole batch would.

    ``episode_options`` (default none) is a function that draws, from an env's own random generator, reset options
    for each of its new episodes, initial and autoreset: a training curriculum, such as more of the specimens a
    policy finds hard (``agents.train_ppo --oversample-radius``). What it returns is checked as ``reset``'s options
    are; the options ``reset(options=...)`` names take precedence. With a seed, its draws repeat as the rest do.

    ``device="cuda"`` steps every env's physics on an NVIDIA GPU, one CUDA thread per env (``pip install -e
    ".[gpu]"``; :mod:`soft_gripper_env.physics.solvers.gpu`): each action's steps in one launch, the same results as
    the CPU's to rounding. The task's reward, observations and infos are computed on the host from the state copied
    back once per action, and returned as NumPy arrays.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": [], "render_fps": 20}

    def __init__(self, num_envs: int = 1, max_episode_steps: int = DEFAULT_MAX_EPISODE_STEPS, num_threads: int = 1,
                 device: str = "cpu", episode_options: Callable[[np.random.Generator], dict] | None = None,
                 **settings) -> None:
        if not isinstance(num_envs, (int, np.integer)) or not 1 <= num_envs <= 100_000:
            raise ValueError(f"num_envs = {num_envs!r} is outside the allowed range [1, 100000]")
        if not isinstance(max_episode_steps, (int, np.integer)) or max_episode_steps < 1:
            raise ValueError(f"max_episode_steps = {max_episode_steps!r} must be a positive integer")
        if not isinstance(num_threads, (int, np.integer)) or not 1 <= num_threads <= min(num_envs, 256):
            raise ValueError(f"num_threads = {num_threads!r} is outside the allowed range [1, {min(num_envs, 256)}] "
                             f"(at most one thread per env)")
        if episode_options is not None and not callable(episode_options):
            raise TypeError(f"episode_options must be a function of a numpy Generator returning reset options, or "
                            f"None; got {type(episode_options).__name__}")
        self.device = check_device(device)
        if self.device == "cuda" and num_threads != 1:
            raise ValueError(f"num_threads = {num_threads!r} with device = 'cuda': the GPU steps every env in one "
                             f"launch; use num_threads = 1")
        self.task = GraspTask(**settings)
        self.num_envs = int(num_envs)
        self.num_threads = int(num_threads)
        self.max_episode_steps = int(max_episode_steps)
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.task.control_dt}
        self.single_action_space = spaces.Box(-1.0, 1.0, (self.task.gripper.n_fingers,), np.float32)
        self._low, self._high = observation_bounds(self.task)
        self.single_observation_space = spaces.Box(self._low, self._high, dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        bounds = np.linspace(0, self.num_envs, self.num_threads + 1).round().astype(int)
        self._shard_ranges = list(zip(bounds[:-1], bounds[1:], strict=True))
        """Each shard's envs, as (first, end) index pairs."""
        self._shards = [_Shard(self.task, end - first, self.max_episode_steps, self._low, self._high, self.device,
                               episode_options) for first, end in self._shard_ranges]
        self._pool = None
        if self.num_threads > 1:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(self.num_threads, thread_name_prefix="soft-gripper-shard")

    def _map(self, method: str, *per_shard):
        """Calls ``method`` of every shard with its share of ``per_shard`` arguments, on the threads if several."""
        calls = [(getattr(shard, method), [args[k] for args in per_shard]) for k, shard in enumerate(self._shards)]
        if self._pool is None:
            return [call(*args) for call, args in calls]
        return list(self._pool.map(lambda item: item[0](*item[1]), calls))

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        if seed is None or isinstance(seed, (int, np.integer)):
            seeds = [None if seed is None else int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"reset got {len(seeds)} seeds for num_envs = {self.num_envs}")
        options = _vector_options(options, "reset option")
        reseed = seed is not None
        parts = self._map("reset", self._split(seeds), [reseed] * len(self._shards), [options] * len(self._shards))
        observations, infos = _joined(parts)
        return observations, _masked(infos)

    def reset_done(self) -> np.ndarray:
        """Resets now every env whose episode ended at the last step, instead of at the next one, and returns the
        observations of all envs: the same-step autoreset that Stable-Baselines3's VecEnv expects."""
        return _joined([(observations,) for observations in self._map("reset_done")])[0]

    def step(self, actions):
        if self._shards[0].batch.sim is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        actions = _check_actions(actions, (self.num_envs,) + self.single_action_space.shape)
        observations, reward, terminated, truncated, infos = _joined(self._map("step", self._split(actions)))
        return observations, reward, terminated, truncated, _masked(infos)

    def set_reward_weights(self, weights: RewardWeights) -> None:
        """Weighs the reward's terms by ``weights`` from the next step on, in every env, without a reset: the rest
        of the task (and so the dynamics, observations and success) is unchanged. For a training curriculum, such as
        a pressure warning that grows once a policy has learnt to close (``agents.train_ppo
        --final-pressure-weight``)."""
        if not isinstance(weights, RewardWeights):
            raise TypeError(f"weights must be a RewardWeights, not {type(weights).__name__}")
        self.task = replace(self.task, reward=weights)
        for shard in self._shards:
            shard.task = shard.batch.task = self.task

    def _split(self, values):
        """``values`` (one per env) cut into the shards' shares."""
        return [values[first:end] for first, end in self._shard_ranges]

    def close_extras(self, **kwargs) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


class _Shard:
    """Consecutive envs of a vector in one batched simulator: their episodes, seeds, step counts and autoresets."""

    def __init__(self, task: GraspTask, size: int, max_episode_steps: int, low: np.ndarray, high: np.ndarray,
                 device: str, episode_options: Callable[[np.random.Generator], dict] | None) -> None:
        self.task, self.size, self.max_episode_steps = task, size, max_episode_steps
        self.episode_options = episode_options
        self.low, self.high = low, high
        self.batch = GraspBatch(task, size, device)
        self.rngs: list[np.random.Generator] = []
        self.steps = np.zeros(size, dtype=np.int64)
        self.autoreset = np.zeros(size, dtype=bool)

    def reset(self, seeds: list[int | None], reseed: bool, options: dict):
        if reseed or not self.rngs:
            self.rngs = [seeding.np_random(s)[0] for s in seeds]
        self._reset_envs(np.arange(self.size), options)
        self.autoreset[:] = False
        infos = _infos(self.batch, _zero_terms(self.size), np.zeros(self.size, dtype=bool))
        return _observations(self.batch, self.low, self.high), infos

    def _reset_envs(self, indices: np.ndarray, options: dict) -> None:
        self.batch.reset(indices, [task_episode(self.task, self.rngs[i], self._options(self.rngs[i], options))
                                   for i in indices], "task")
        self.steps[indices] = 0

    def _options(self, rng: np.random.Generator, options: dict) -> dict:
        """An episode's reset options: those the curriculum (``episode_options``) draws from the env's generator,
        checked, under those ``reset`` was given."""
        if self.episode_options is None:
            return options
        return {**_vector_options(self.episode_options(rng), "episode_options drew"), **options}

    def reset_done(self) -> np.ndarray:
        done = np.nonzero(self.autoreset)[0]
        if len(done):
            self._reset_envs(done, {})
            self.autoreset[done] = False
        return _observations(self.batch, self.low, self.high)

    def step(self, actions: np.ndarray):
        active = ~self.autoreset
        outcome = self.batch.step(actions, active)
        self.steps[active] += 1
        terminated = outcome.terminated.copy()
        truncated = outcome.truncated | (active & ~terminated & (self.steps >= self.max_episode_steps))
        reward = outcome.reward.copy()
        terms = outcome.reward_terms
        restarting = np.nonzero(self.autoreset)[0]
        if len(restarting):
            self._reset_envs(restarting, {})
            reward[restarting] = 0.0
            terms = {name: np.where(active, value, 0.0) for name, value in terms.items()}
        infos = _infos(self.batch, terms, outcome.solver_failure)
        self.autoreset = terminated | truncated
        return _observations(self.batch, self.low, self.high), reward, terminated, truncated, infos


def _vector_options(options: dict | None, source: str) -> dict:
    """``options`` checked as ``reset``'s are (:func:`~.grasp_task.check_options`), for a vector env's episodes,
    which are the task's: the paper's scene is the single env's. ``source`` says in the error where they came from."""
    checked = check_options(options)
    if checked.get("scene", "task") != "task":
        raise ValueError(f"{source} scene = {checked['scene']!r} is for the single env (gym.make), not a vector")
    return checked


def _joined(parts: list[tuple]) -> tuple:
    """The shards' results (tuples of arrays and dicts of them) joined along the envs, or the one shard's as is."""
    if len(parts) == 1:
        return parts[0]
    return tuple(_join([part[k] for part in parts]) for k in range(len(parts[0])))


def _join(values: list):
    if isinstance(values[0], dict):
        return {key: _join([value[key] for value in values]) for key in values[0]}
    return np.concatenate(values)


def _masked(infos: dict[str, Any]) -> dict[str, Any]:
    """Gymnasium's vector info layout: each key's array, and a ``"_key"`` mask of the envs that report it (all)."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        if isinstance(value, dict):
            value = _masked(value)
            size = len(next(iter(infos[key].values())))
        else:
            size = len(value)
        out[key] = value
        out["_" + key] = np.ones(size, dtype=bool)
    return out


__all__ = ["SoftGripperUnderwaterEnv", "SoftGripperUnderwaterVectorEnv", "DEFAULT_MAX_EPISODE_STEPS",
           "observed_parts", "observation_slices", "observation_bounds"]
