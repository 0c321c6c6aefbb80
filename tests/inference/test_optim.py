"""The K_t optimiser's Newton code (torch_gpioius.inference.optim.newton_maximize) on functions known in closed form."""

import math

import numpy as np

from torch_gpioius.inference.optim import newton_maximize


def _cosine(calls):
    """f(x) = cos(3x) on one coordinate: a maximum at 0 (f'' = -9), convex and rising at x = -0.9."""
    def value(phi):
        x = float(phi[0])
        calls.append(x)
        return math.cos(3 * x), np.array([-3 * math.sin(3 * x)]), np.array([[-9 * math.cos(3 * x)]])
    return value


def test_a_step_to_the_edge_that_falls_is_refused_once_and_the_hessian_returned_is_the_maximums():
    """From x = -0.9, where cos(3x) is convex and rising, the step to the trust region's edge (x = 1.1) falls: it is
    refused and not evaluated again, later edge steps are a quarter as long (0.5), and the run reaches the
    maximum at 0; the Hessian returned is the one at the end (-9), not the refused trial's (+8.9 at 1.1)."""
    calls = []
    phi, f, pg, it, converged, hess = newton_maximize(_cosine(calls), np.array([-0.9]), np.array([-5.0]),
                                                      np.array([5.0]), caps=lambda p: np.array([2.0]),
                                                      return_hessian=True)
    assert converged and abs(float(phi[0])) < 1e-6 and f == math.cos(3 * float(phi[0]))
    assert calls.count(calls[1]) == 1 and calls[1] == -0.9 + 2.0          # the edge trial, once
    assert [c for c in calls if c > 0.3] == [calls[1]]                    # later edge steps a quarter as long
    np.testing.assert_allclose(hess, [[-9.0]], atol=1e-5)
    # without return_hessian the result is the same five values as before
    assert len(newton_maximize(_cosine([]), np.array([-0.9]), np.array([-5.0]), np.array([5.0]),
                               caps=lambda p: np.array([2.0]))) == 5


def test_a_function_convex_and_rising_along_a_coordinate_is_climbed_to_the_edge_not_crept_along():
    """f(w) = e^(2w) - e^(4w) / 4 (the likelihood's dependence on ``w = log L[1,1]`` near a correlation of 1, with a
    maximum at z = e^(2w) = 2): from w = -12, where the gradient is 2e-10, below the gradient tolerance, the run
    climbs in edge steps (each accepted, z times e^4) and then converges at w = log(2) / 2; a trial point refused
    once is not evaluated again."""
    calls = []

    def value(phi):
        w = float(phi[0])
        calls.append(w)
        z = math.exp(2 * w)
        return z - z * z / 4, np.array([2 * z - z * z]), np.array([[4 * z - 4 * z * z]])

    phi, f, pg, it, converged = newton_maximize(value, np.array([-12.0]), np.array([-12.0]), np.array([12.0]),
                                                caps=lambda p: np.array([2.0]))
    assert converged and abs(float(phi[0]) - 0.5 * math.log(2)) < 1e-6 and abs(f - 1.0) < 1e-12
    assert calls[:6] == [-12.0, -10.0, -8.0, -6.0, -4.0, -2.0] and len(calls) < 20
    assert calls.count(2.0) == 1              # past the maximum, the edge is refused once: not again as damping grows
    # without a trust region (caps=None) the run keeps the old behaviour: it stops where the gradient is tiny
    phi, *_ = newton_maximize(value, np.array([-12.0]), np.array([-12.0]), np.array([12.0]))
    assert float(phi[0]) < -10


def test_with_the_value_alone_refused_trials_and_edge_walks_cost_no_derivatives():
    """``level`` (the function's value alone) judges trial points first, and an edge step walks on along its
    coordinate while the value rises: the run reaches the same maximum as without it, and ``value`` (with the
    derivatives) is asked at the start and where steps end, never at a refused trial (the cosine's edge step to 1.1;
    the exponential's past its maximum). From w = -12 the exponential's walk climbs -10, -8, ..., 0 by values alone
    (it rises all the way: the maximum is at log(2) / 2) and asks the derivatives first at 0."""
    def run(value, start, with_level):
        points, derived = [], []

        def counted(phi):
            derived.append(float(phi[0]))
            return value(phi)

        def level(phi):
            points.append(float(phi[0]))
            return value(phi)[0]

        result = newton_maximize(counted, np.array([start]), np.array([-12.0]), np.array([12.0]),
                                 caps=lambda p: np.array([2.0]), level=level if with_level else None)
        return result, points, derived

    def exponential(phi):
        z = math.exp(2 * float(phi[0]))
        return z - z * z / 4, np.array([2 * z - z * z]), np.array([[4 * z - 4 * z * z]])

    for value, start, top, refused in ((_cosine([]), -0.9, 0.0, 1.1), (exponential, -12.0, 0.5 * math.log(2), 2.0)):
        plain, _, plain_points = run(value, start, False)
        judged, points, derived = run(value, start, True)
        assert plain[4] and judged[4]                                            # both converged
        assert abs(float(judged[0][0]) - top) < 1e-6 and abs(judged[1] - plain[1]) < 1e-12
        assert any(abs(p - refused) < 1e-12 for p in points)                     # the refused trial: judged ...
        assert not any(abs(p - refused) < 1e-12 for p in derived)                # ... by its value alone
        assert len(derived) < len(plain_points)
    assert derived[:2] == [-12.0, 0.0] and points[:6] == [-10.0, -8.0, -6.0, -4.0, -2.0, 0.0]
