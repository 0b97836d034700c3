"""The physics core: discrete elastic rod fingers, force models, contact and implicit time stepping.

Pure NumPy/SciPy with Numba-compiled kernels; it never imports gymnasium, torch or stable-baselines3. Its layers,
each importing only those below it (``docs/design.md``): :mod:`.scene` (descriptions) → :mod:`.kernels` (compiled
per-rod functions) → :mod:`.solvers` (Newton, the contact corrector, the integrators) → :mod:`.simulator`.
"""

from .kernels.assembly import StepContext, evaluate_force
from .kernels.current import current_at
from .scene.design import (
    ELASTOSIL_MA_4601,
    SILICONE_RETARDATION_TIME,
    SOFT_TRANSLUCENT_SILICONE,
    FingerDesign,
    GripperDesign,
    Material,
    linear_taper,
    paper_finger,
    without_material_damping,
)
from .scene.discretization import Discretization
from .scene.fluid import WATER, WATER_DENSITY, WATER_VISCOSITY, Current, Fluid
from .scene.forces import (
    PAPER_DEFECTIVE_DRAG,
    AddedMass,
    BodyLoads,
    Buoyancy,
    ForceModel,
    Gravity,
    MassProportionalDamping,
    MorisonDrag,
    StokesDrag,
    fluid_forces,
)
from .scene.objects import (
    DEFAULT_FRICTION,
    PAPER_BALL,
    PENETRATION_ACCELERATION,
    PENETRATION_TOLERANCE,
    Capsule,
    ContactSettings,
    Sphere,
    penetration_tolerance,
)
from .scene.scene import (
    INTEGRATOR_NAMES,
    NATURAL_CURVATURE_LIMIT,
    NewtonSettings,
    Scene,
    cantilever_scene,
    paper_scene,
)
from .scene.validation import check_range
from .simulator import Simulator, Trajectory, run_ramp
from .solvers.gpu import GpuUnavailable, GpuUnsupported, check_device
from .solvers.records import ContactReport, RodState, StepResult, put_grippers, take_grippers

__all__ = [
    "ELASTOSIL_MA_4601", "SILICONE_RETARDATION_TIME", "SOFT_TRANSLUCENT_SILICONE", "FingerDesign", "GripperDesign",
    "Material", "linear_taper", "without_material_damping",
    "paper_finger", "Discretization", "WATER", "WATER_DENSITY", "WATER_VISCOSITY", "Current", "current_at", "Fluid",
    "PAPER_DEFECTIVE_DRAG", "AddedMass", "BodyLoads", "Buoyancy", "ForceModel", "Gravity", "MassProportionalDamping",
    "MorisonDrag", "StokesDrag", "fluid_forces", "PAPER_BALL", "PENETRATION_TOLERANCE", "DEFAULT_FRICTION", "Capsule",
    "PENETRATION_ACCELERATION", "penetration_tolerance",
    "ContactSettings",
    "Sphere", "INTEGRATOR_NAMES", "NATURAL_CURVATURE_LIMIT", "NewtonSettings", "Scene", "cantilever_scene",
    "paper_scene", "check_range", "Simulator", "Trajectory", "run_ramp", "ContactReport", "RodState", "StepResult",
    "put_grippers", "take_grippers", "StepContext", "evaluate_force", "GpuUnavailable", "GpuUnsupported",
    "check_device",
]
