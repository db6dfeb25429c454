"""Layouts of the arrays the numba kernels read and write: named indices, one place.

The kernels take the problem as two flat float arrays, so that one compiled loop serves every
harvester: ``pp`` (the physical parameters, :func:`montecarlo.coefficients.physical_vector`) and
``cf`` (the coefficients of one step size h, :func:`montecarlo.coefficients.step_coefficients`
and each step's :meth:`~montecarlo.steps.base.Stepper.coefficients`). Each entry has a name here;
the code that fills the arrays and the kernels that read them use the names. numba compiles a
module-level integer as a constant, so ``pp[P_SIGMA]`` is the same machine code as ``pp[5]``.

``pp`` (length :data:`P_SIZE`)
    m, gamma, K_v, K_c, tau_p, sigma, the coupling k, a, n; ``P_STIFFNESS`` the stiffness c kept
    inside the exactly integrated linear flow (:func:`montecarlo.coefficients.linear_stiffness`);
    ``P_THRESHOLD`` the escape amplitude; ``P_XI_VAR`` the stationary variance D/tau of xi;
    ``P_KINK_RULE`` the kink's rule for swings shorter than the step, the number of full swings
    that must fit in the time left before they are averaged (:data:`montecarlo._kink.AVERAGE`;
    ``HOLD`` = 0, never); ``P_KINK_FORCE`` the strength :math:`an` of
    the part :math:`-an\\,\\mathrm{sign}(x)` of the force that the kink's flow integrates exactly
    (0 for the other on-site kinds); the bi-Laplacian and cubic couplings k4 and k3 (0 for a
    single unit, like k).
``cf`` (common part, length :data:`CF_STEP`; each step appends its own entries from ``CF_STEP``)
    ``CF_E`` the 3x3 propagator :math:`E = e^{Ah}` of the linear part of (x, v, V), row-major;
    ``CF_G`` its response :math:`g = \\int_0^h e^{As}b\\,ds` to a unit constant force (3);
    ``CF_H`` the step h; ``CF_XI_DECAY`` :math:`e^{-h/\\tau}`; ``CF_XI_NOISE``
    :math:`\\sqrt{(D/\\tau)(1 - e^{-2h/\\tau})}`; ``CF_XI_HALF`` the factor on the measured
    :math:`v\\xi` (:math:`e^{-h/2\\tau}` when xi is measured half a step before its update, 1
    when after); ``CF_SUB_E``, ``CF_SUB_G``: E and g of the substep ``h /``
    :data:`montecarlo._kernels.MAX_SUBSTEPS` (the stiff walls' substeps build ``h/K`` from them
    by squaring); ``CF_PVX`` 1 when :math:`v\\xi` is measured from the step's own estimate
    ``pvx`` (its conditional expectation), 0 when as v times the measured xi.
"""

from __future__ import annotations

__all__ = [
    "KIND_LINEAR", "KIND_KICK", "KIND_KINK",
    "P_M", "P_GAMMA", "P_KV", "P_KC", "P_TAU_P", "P_SIGMA", "P_K", "P_A", "P_N", "P_STIFFNESS",
    "P_THRESHOLD", "P_XI_VAR", "P_KINK_RULE", "P_KINK_FORCE", "P_K4", "P_K3", "P_SIZE",
    "CF_E", "CF_G", "CF_H", "CF_XI_DECAY", "CF_XI_NOISE", "CF_XI_HALF", "CF_SUB_E", "CF_SUB_G", "CF_PVX",
    "CF_STEP",
    "C_SLOW", "C_CROSSINGS", "C_AVERAGED", "C_EXHAUSTED", "C_RING_STEPS", "N_COUNTERS",
    "MOMENTS", "N_MOM", "ROWS", "M_V2", "M_vV", "M_v2", "M_x2", "M_vxi", "M_stuck", "M_xdU", "M_TWIN", "M_d2",
]

#: On-site treatment of -U'(x) (:func:`montecarlo.coefficients.onsite_kind`): inside the exact
#: linear flow (harmonic), Strang kicks (smooth n), the kink's exact piecewise flow (n near 1).
KIND_LINEAR = 0
KIND_KICK = 1
KIND_KINK = 2

# pp: the physical parameters
P_M = 0
P_GAMMA = 1
P_KV = 2
P_KC = 3
P_TAU_P = 4
P_SIGMA = 5
P_K = 6
P_A = 7
P_N = 8
P_STIFFNESS = 9
P_THRESHOLD = 10
P_XI_VAR = 11
P_KINK_RULE = 12
P_KINK_FORCE = 13
P_K4 = 14
P_K3 = 15
P_SIZE = 16

# cf: the coefficients of one step size, common part
CF_E = 0
CF_G = 9
CF_H = 12
CF_XI_DECAY = 13
CF_XI_NOISE = 14
CF_XI_HALF = 15
CF_SUB_E = 16
CF_SUB_G = 25
CF_PVX = 28
#: First entry of a step's own coefficients (and length of the common part).
CF_STEP = 29

# the loop's counters (``Sums.counters``): the kink's statistics and the ring steps taken
#: unit-steps on the kink's slow path (near x = 0)
C_SLOW = 0
#: located zero crossings
C_CROSSINGS = 1
#: entries into the averaged swing map
C_AVERAGED = 2
#: steps that exhausted the event budget
C_EXHAUSTED = 3
#: ring steps taken, all levels
C_RING_STEPS = 4
N_COUNTERS = 5

#: Moments accumulated per level, in this order: the system's (``xdU`` is
#: :math:`x\\,U'(x)`, for the statistical linearization), prefixed ``t_`` the harmonic
#: twin's (fine level only; zero without a twin), and the bond's :math:`(x_{j+1} - x_j)^2`
#: (``d2``, 0 for a single unit; last so that the twin's slots keep their place).
MOMENTS = ("V2", "vV", "v2", "x2", "vxi", "stuck", "xdU",
           "t_V2", "t_vV", "t_v2", "t_x2", "t_vxi",
           "t_x4", "t_x2V2", "t_x2v2", "t_absxn", "t_V2v2", "t_vxiV2", "d2")
N_MOM = len(MOMENTS)
#: Rows of the ``sums`` accumulator: fine level, coarse level, fine level over the first half
#: of the measured window (the burn-in drift check compares it with the whole), and the
#: coarsest level (twice the coarse step, only with ``third``).
ROWS = 4
# the moments' slots
M_V2 = MOMENTS.index("V2")
M_vV = MOMENTS.index("vV")
M_v2 = MOMENTS.index("v2")
M_x2 = MOMENTS.index("x2")
M_vxi = MOMENTS.index("vxi")
M_stuck = MOMENTS.index("stuck")
M_xdU = MOMENTS.index("xdU")
#: first of the twin's moments (:data:`montecarlo.controls.twin.TWIN_MOMENTS`, in that order)
M_TWIN = MOMENTS.index("t_V2")
M_d2 = MOMENTS.index("d2")

