"""The one decorator the physics compiles with (soft_gripper_env/physics/kernels/compiled.py)."""

import importlib
import pkgutil
import textwrap

import numpy as np
import pytest
from numba import types
from numba.core.dispatcher import Dispatcher

import soft_gripper_env.physics as physics
from soft_gripper_env.physics.kernels.compiled import kernel


@kernel
def _sum_of_squares(values):
    total = 0.0
    for value in values:
        total += value * value
    return total


@kernel(python=True)
def _norm(values):
    return np.sqrt(_sum_of_squares(values))


def _python_entry(dispatcher) -> int:
    """The address of the CPython wrapper of ``dispatcher`` compiled for a float64 vector, compiled or loaded from
    the cache here (0: none was built)."""
    signature = (types.float64[::1],)
    dispatcher.compile(signature)
    compiled = dispatcher.overloads[signature]
    return compiled.library.get_pointer_to_function(compiled.fndesc.llvm_cpython_wrapper_name)


def test_a_kernel_that_python_does_not_call_compiles_without_an_entry_point_and_its_callers_still_run():
    assert _norm(np.array([3.0, 4.0])) == 5.0
    assert _python_entry(_norm) != 0
    assert _python_entry(_sum_of_squares) == 0  # compiled for its caller, without the wrapper


def test_calling_a_kernel_only_kernel_from_python_raises_a_clear_error_instead_of_crashing():
    with pytest.raises(TypeError, match=r"_sum_of_squares is compiled to be called from other compiled kernels.*"
                                        r"python=True"):
        _sum_of_squares(np.array([1.0]))


@kernel(runtime=True)  # it allocates
def _fresh_zeros(n):
    return np.zeros(n)


@kernel
def _pair(first, second):
    return first, second


@kernel(python=True)
def _size_of_fresh_zeros(n):
    return _fresh_zeros(n).size


@kernel(python=True, runtime=True)
def _sum_of_pair_with_runtime(first, second):
    bundle = _pair(first, second)
    return bundle[0].sum() + bundle[1].sum()


@kernel(python=True)
def _sum_of_pair(first, second):
    bundle = _pair(first, second)
    return bundle[0].sum() + bundle[1].sum()


@kernel(python=True)
def _doubled_in_place(values):
    for i in range(values.size):
        values[i] *= 2.0
    return values


@kernel
def _allocates_without_the_runtime(n):
    return np.zeros(n).sum()


@kernel(python=True)
def _calls_a_kernel_that_allocates_without_the_runtime(n):
    return _allocates_without_the_runtime(n)


def test_an_allocation_without_the_runtime_fails_to_compile_naming_the_kernel_and_the_fix():
    from numba.core.errors import TypingError

    with pytest.raises(TypingError, match=r"(?s)_allocates_without_the_runtime is compiled without Numba's runtime.*"
                                          r"@kernel\(runtime=True\)") as raised:
        _calls_a_kernel_that_allocates_without_the_runtime(3)
    assert "_calls_a_kernel_that_allocates_without_the_runtime is compiled" not in str(raised.value)


def test_an_array_returned_by_a_kernel_with_the_runtime_to_one_without_is_refused_when_it_compiles():
    with pytest.raises(TypeError, match=r"_size_of_fresh_zeros \(compiled without Numba's runtime\) receives arrays "
                                        r".* where .*_fresh_zeros is compiled with Numba's runtime"):
        _size_of_fresh_zeros(4)


def test_an_array_returned_by_a_kernel_without_the_runtime_to_one_with_it_is_refused_when_it_compiles():
    with pytest.raises(TypeError, match=r"_sum_of_pair_with_runtime \(compiled with Numba's runtime\) receives "
                                        r"arrays .* where .*_pair is compiled without"):
        _sum_of_pair_with_runtime(np.arange(4.0), np.ones(2))


def test_kernels_without_the_runtime_pass_arrays_to_each_other_and_count_nothing():
    import sys

    first, second = np.arange(6.0), np.ones(2)
    held = sys.getrefcount(first), sys.getrefcount(second)
    for _ in range(3):
        assert _sum_of_pair(first, second) == 17.0
    assert (sys.getrefcount(first), sys.getrefcount(second)) == held


def test_a_kernel_python_calls_may_not_return_an_array_without_the_runtime():
    with pytest.raises(TypeError, match=r"_doubled_in_place is called from Python and returns arrays .* "
                                        r"runtime=True"):
        _doubled_in_place(np.ones(3))


def test_the_cache_keys_a_kernel_by_its_options_so_a_changed_mode_compiles_again():
    from numba.core.registry import cpu_target

    def square(x):
        return x * x

    keys = {}
    for runtime in (False, True):
        dispatcher = kernel(runtime=runtime)(square)
        keys[runtime] = dispatcher._cache._index_key((types.float64,), cpu_target.target_context.codegen())
    assert keys[False][:-1] == keys[True][:-1] and keys[False][-1] != keys[True][-1]


def test_no_kernel_returns_a_local_array():
    """:func:`~soft_gripper_env.physics.kernels.local.local_array` lives on its function's stack: returned, it
    would point at memory that the next call overwrites. Read from the source: no return statement of a kernel
    names a variable bound to one (itself, sliced, or in a tuple)."""
    import ast
    import inspect

    offenders, checked = [], 0
    for name, dispatcher in _physics_dispatchers():
        function = ast.parse(textwrap.dedent(inspect.getsource(dispatcher.py_func))).body[0]
        local = set()
        for node in ast.walk(function):
            if isinstance(node, ast.Assign):
                call = node.value.value if isinstance(node.value, ast.Subscript) else node.value
                if isinstance(call, ast.Call) and getattr(call.func, "id", None) == "local_array":
                    local |= {n.id for target in node.targets for n in ast.walk(target) if isinstance(n, ast.Name)}
        checked += bool(local)
        for node in ast.walk(function):
            if isinstance(node, ast.Return) and node.value is not None:
                returned = {n.id for n in ast.walk(node.value) if isinstance(n, ast.Name)} & local
                if returned:
                    offenders.append(f"{name} returns {sorted(returned)}")
    assert checked > 10  # the kernels that make local arrays were read
    assert not offenders, offenders


@pytest.mark.parametrize("argument", ["python", "inline", "runtime"])
def test_the_decorator_refuses_an_option_that_is_not_a_bool(argument):
    with pytest.raises(TypeError, match=f"kernel\\({argument}=...\\) must be a bool"):
        kernel(**{argument: "yes"})


def _physics_dispatchers():
    for module_info in pkgutil.walk_packages(physics.__path__, physics.__name__ + "."):
        module = importlib.import_module(module_info.name)
        for name, value in vars(module).items():
            if isinstance(value, Dispatcher) and value.py_func.__module__ == module.__name__:
                yield f"{module.__name__}.{name}", value


def test_every_compiled_function_of_the_physics_is_made_by_the_one_decorator():
    dispatchers = dict(_physics_dispatchers())
    assert len(dispatchers) > 50
    for name, dispatcher in dispatchers.items():
        options = dispatcher.targetoptions
        assert options.get("nogil") is True and options.get("error_model") == "numpy", name
        assert options.get("inline") in ("always", "never"), name
        assert options.get("_nrt") in (True, False), f"{name} does not say whether it has the runtime"
        assert type(dispatcher._cache).__name__ != "NullCache", f"{name} is not cached"
        internal = options.get("no_cpython_wrapper", False)
        assert (type(dispatcher).__name__ == "KernelOnlyDispatcher") == internal, name


def _arrays_reachable_from(root) -> list[np.ndarray]:
    """Every NumPy array reachable from ``root`` through attributes, tuples, lists and dicts (the garbage collector
    does not track arrays, so it cannot list them)."""
    found, seen, pending = [], set(), [root]
    while pending:
        item = pending.pop()
        if id(item) in seen or isinstance(item, (str, bytes, int, float, bool, type(None), type)):
            continue
        seen.add(id(item))
        if isinstance(item, np.ndarray):
            found.append(item)
        elif isinstance(item, (tuple, list, set, frozenset)):
            pending.extend(item)
        elif isinstance(item, dict):
            pending.extend(item.values())
        elif hasattr(item, "__dict__") and not callable(item) and type(item).__module__.startswith("soft_gripper"):
            pending.extend(vars(item).values())
        elif hasattr(item, "__slots__") and type(item).__module__.startswith("soft_gripper"):
            pending.extend(getattr(item, name) for name in item.__slots__ if hasattr(item, name))
    return found


def _leaks(root, step, repeats: int) -> tuple[int, int, list]:
    """Runs ``step()`` ``repeats`` times and returns how many of Numba's arrays it made and freed, and the arrays
    reachable from ``root`` whose Python reference count grew meanwhile (its ``(before, after, shape)``)."""
    import sys

    from numba.core.runtime import _nrt_python, rtsys

    arrays = _arrays_reachable_from(root)  # held here, so the same holders both times
    before = [sys.getrefcount(a) for a in arrays]
    _nrt_python.memsys_enable_stats()  # Numba's own allocations, which Python's counts cannot see
    try:
        allocated = rtsys.get_allocation_stats()
        for _ in range(repeats):
            step()
        allocated_after = rtsys.get_allocation_stats()
    finally:
        _nrt_python.memsys_disable_stats()
    after = [sys.getrefcount(a) for a in arrays]  # counted as before was, with the same temporaries
    assert len(arrays) > 20  # the state's and the simulator's own arrays were seen
    grown = [(was, now, a.shape) for a, was, now in zip(arrays, before, after, strict=True) if now > was]
    return allocated_after.mi_alloc - allocated.mi_alloc, allocated_after.mi_free - allocated.mi_free, grown


@pytest.mark.parametrize("model", ["3d", "planar"])
def test_env_steps_leave_no_array_referenced_more_than_before(model):
    """Every array Python hands the kernels comes back with its reference count as it was, and every array the
    kernels make is freed: a kernel that kept a reference (a bundle returned across the boundary between code
    compiled with Numba's reference counting and code without it, docs/notes/compile_time.md) would leave an
    array one reference higher per call, and never free it."""
    import gymnasium as gym

    env = gym.make("SoftGripperUnderwater-v0", model=model)
    env.reset(seed=0)
    closing = np.full(env.action_space.shape, -0.6, dtype=np.float32)
    for _ in range(8):  # the fingers reach the sphere: the corrector and the free body's coupling run
        env.step(closing)
    made, freed, grown = _leaks(env.unwrapped, lambda: env.step(closing), 12)
    assert made > 0 and freed == made, f"{made} of Numba's arrays made over 12 env steps, {freed} freed"
    assert not grown, f"{len(grown)} arrays gained references over 12 env steps: {grown[:5]}"
    env.close()


@pytest.mark.parametrize("path", ["halved on the host", "one step at a time", "rods alone"])
def test_the_simulators_other_entry_points_leave_no_array_referenced_more_than_before(path):
    """The same for the simulator's compiled entry points besides the env's: a batch whose steps the host halves
    for some grippers (``gripper_views``, ``gripper_body`` and ``take_steps`` on one gripper's rows), ``step``'s
    predictor–corrector against the paper's fixed ball (``solve_with_contact``), and fingers with nothing to grasp
    (``advance_rods``)."""
    from dataclasses import replace

    from soft_gripper_env.grasp_task import GraspTask, task_episode
    from soft_gripper_env.physics import PAPER_BALL, NewtonSettings, Simulator, paper_scene

    if path == "halved on the host":  # two Newton iterations are too few for the impacts: steps are halved
        rng = np.random.default_rng(3)
        scenes = [replace(task_episode(GraspTask(model="planar"), rng, {}).scene,
                          newton=NewtonSettings(max_iterations=2)) for _ in range(4)]
        sim = Simulator(scenes)
        halved = []
        halve = sim._halve_pending
        sim._halve_pending = lambda *args: (halved.append(len(args[-1])), halve(*args))
        state = sim.initial_state()
        rate = np.array([[-1.0] * 3, [-0.6] * 3, [0.0] * 3, [-1.0] * 3])

        def step():
            sim.advance(state, np.full((4, 3), -0.2), rate, 5)
    elif path == "one step at a time":
        sim = Simulator(paper_scene("planar", grasped_object=PAPER_BALL))
        state = sim.initial_state()
        for k in range(1, 101):  # the paper's ramp closes the fingers onto the ball in its second
            state = sim.step(state, np.full((1, 3), -0.15 * k * sim.scene.time_step)).state

        def step():
            sim.step(state, np.full((1, 3), -0.15))
    else:
        sim = Simulator(paper_scene("3d"))
        state = sim.initial_state()

        def step():
            sim.step(state, np.full((1, 3), -0.15))

    step()  # compiled (or loaded), and each scratch array the first call makes once
    made, freed, grown = _leaks(sim, step, 6)
    if path == "halved on the host":
        assert halved, "no step was halved on the host"
    elif path == "one step at a time":
        assert sim.step(state, np.full((1, 3), -0.15)).contact.normal_reaction.max() > 0.0  # on the ball
    assert made > 0 and freed == made, f"{made} of Numba's arrays made, {freed} freed"
    assert not grown, f"{len(grown)} arrays gained references: {grown[:5]}"
