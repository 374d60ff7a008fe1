"""genesis_lite: a differentiable multi-solver physics simulator with Genesis's API.

    import genesis_lite as gs
    gs.init(precision="64")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True))
"""
import gc
import os

# Taichi's CPU kernels and torch's OpenMP threads share the cores. After each parallel torch op (a
# copy of a state, an autograd step) libgomp's threads spin by default, and the Taichi kernel that
# follows runs on the cores they hold: measured on 2 cores, the MPM backward per step 40.9–44.1 ms
# with spinning, 34.4–34.5 ms with passive waiting. It takes effect only where torch is first
# imported by this import; a policy the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# The import makes ~40k objects (modules, classes, functions: they live on) next to torch's ~170k;
# the garbage collector's passes over all of them took 0.08 of the import's 0.26 s, after torch's.
_collecting = gc.isenabled()
gc.disable()
try:
    from . import materials, morphs, options, surfaces, utils
    from .options import constraint_solver, friction_cone, link_ref_frame
    from .solvers.core import (AssetError, GenesisException, GradientError, InvalidInputError, SceneStateError,
                               SimulationError)
    from .runtime import cpu, destroy, gpu, init, logger, runtime
    from .scene import Scene, SimState
    from .utils.geom import *  # noqa: F401,F403 (Genesis's gs.<name> of every gs.utils.geom function)
    from .tensor import (Tensor, from_numpy, from_torch, ones, ones_like, rand, randn, tensor, zeros,
                         zeros_like)
finally:
    if _collecting:
        gc.enable()
    del _collecting

__version__ = "0.1.0"


def __getattr__(name):
    # gs.device and the dtypes depend on gs.init(), so they are looked up when asked for
    if name in ("device", "tc_float", "np_float", "ti_float", "tc_int", "np_int", "tc_bool", "np_bool"):
        return getattr(runtime, name)
    raise AttributeError(f"module 'genesis_lite' has no attribute {name!r}")
