"""A stepper's fast kernel is its general step where it accepts, bit for bit, and changes
nothing where it declines (a stiff wall, the kink)."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from fpe_harvester import Harvester
from montecarlo.layout import KIND_KICK, KIND_KINK, KIND_LINEAR
from montecarlo._kink import N_TAYLOR
from montecarlo.coefficients import physical_vector
from montecarlo.steps import STEPPERS

N, P = 3, 4

# (stepper, harvester, kind, dt, amplitude of the random state, whether the fast kernel accepts)
CASES = [
    ("frozen", dict(N=N, a=1.0, n=2), KIND_LINEAR, 0.05, 1.0, True),
    ("frozen", dict(N=N, a=1.0, n=3, k4=0.1, k3=0.2), KIND_KICK, 0.05, 1.0, True),
    ("frozen", dict(N=1, a=1.0, n=3), KIND_KICK, 0.05, 1.0, True),
    ("frozen", dict(N=N, a=1.0, n=6), KIND_KICK, 0.2, 3.0, False),   # a path near the stiff wall
    ("frozen", dict(N=N, a=1.0, n=1), KIND_KINK, 0.05, 1.0, False),
]


def _arguments(step: str, h: Harvester, kind: int, dt: float, amp: float, seed: int) -> dict:
    """Every argument of the step protocol (``dispatch.STEP_ARGS``), a random state."""
    rng = np.random.default_rng(seed)
    n = h.N

    def field(scale: float = 1.0) -> np.ndarray:
        return scale * rng.standard_normal((n, P))

    x = field(amp)
    pp = physical_vector(h, 1e6, kind=kind)
    F = np.zeros((n, P)) if kind == KIND_LINEAR else -h.a * h.n * np.sign(x) * np.abs(x) ** (h.n - 1)
    return dict(x=x, v=field(amp), V=field(), xi=field(), F=F, stuck=np.zeros((n, P), dtype=np.bool_),
                pvx=np.zeros((n, P)), eps=rng.standard_normal((STEPPERS[step].kernels.normals, n, P)),
                cf=STEPPERS[step].coefficients(h, dt), pp=pp, kind=kind, xm=np.zeros((n, P)),
                fext=np.zeros((n, P)), cs=np.zeros((3, N_TAYLOR + 1)), rbm=np.zeros((n, P)),
                rbx=np.zeros((n, P)), w=np.ones(P), counters=np.zeros(5, dtype=np.int64),
                gen=np.random.Generator(np.random.PCG64(seed)))


def _call(kernel, args: dict):
    return kernel(*[args[name] for name in inspect.signature(kernel.py_func).parameters])


def _copy(args: dict) -> dict:
    out = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in args.items()}
    out["gen"] = np.random.Generator(np.random.PCG64(0))
    return out


@pytest.mark.parametrize("step, params, kind, dt, amp, accepts", CASES)
def test_fast_step_is_the_general_step(step, params, kind, dt, amp, accepts):
    kernels = STEPPERS[step].kernels
    assert kernels.fast is not None
    h = Harvester.build(**params)
    for seed in range(3):
        args = _arguments(step, h, kind, dt, amp, seed)
        general, fast = _copy(args), _copy(args)
        _call(kernels.step, general)
        done = _call(kernels.fast, fast)
        assert done == accepts
        if not done:
            for name, value in args.items():
                if isinstance(value, np.ndarray):
                    assert np.array_equal(fast[name], value), f"declined but changed {name}"
            _call(kernels.step, fast)
        for name, value in general.items():
            if isinstance(value, np.ndarray):
                assert np.array_equal(fast[name], value), f"{name} differs"
