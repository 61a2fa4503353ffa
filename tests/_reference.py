"""Independent references for the tests: scipy `solve_ivp` event-driven simulation written the
way users write it (restart at each event), used only to check pwsdyn."""

import numpy as np
from scipy.integrate import solve_ivp


def scipy_impacting(rhs, surface, reset, y0, t_span, rtol=1e-12, atol=1e-12, max_events=10_000):
    """Event-driven scipy simulation of a single impact surface (direction -1)."""
    def event(t, y):
        return surface(t, y)
    event.terminal = True
    event.direction = -1
    t0, t1 = t_span
    y = np.asarray(y0, float)
    times, before, after = [], [], []
    while t0 < t1 and len(times) < max_events:
        sol = solve_ivp(rhs, (t0, t1), y, method="DOP853", events=event, rtol=rtol, atol=atol)
        if sol.status == 1 and sol.t_events[0].size:
            te = sol.t_events[0][0]
            ye = sol.y_events[0][0]
            if times and te - times[-1] < 1e-12:
                # the restart re-detected the event it started on: step past it
                y = sol.y[:, -1]
                t0 = sol.t[-1]
                continue
            times.append(te)
            before.append(ye.copy())
            ya = reset(te, ye)
            after.append(ya.copy())
            t0, y = te, ya
        else:
            t0, y = sol.t[-1], sol.y[:, -1]
            break
    return np.array(times), np.array(before), np.array(after), y
