"""The compiled event-driven integrator (numba).

One function, :func:`run_kernel`, integrates a hybrid model from ``t0`` to ``t_end`` with an
embedded explicit Runge-Kutta pair and handles every discontinuity in the same compiled loop:
no Python call is made per step or per event. The model enters as one first-class function
``evaluate(which, idx, t, x, p, out)`` (see :mod:`pwsdyn.model.codegen`), so this kernel is
compiled once for all models and cached on disk.

Discrete state
--------------
``dkind`` is what governs the motion now:

* ``REGULAR``: the vector field of mode ``mode``;
* ``STICK``: sticking on the surface of impact event ``didx`` after a complete chattering
  sequence, or after an impact that leaves the normal velocity at round-off while the free
  motion presses into the surface (a plastic impact, an impact at rest): constrained motion
  ``f - lambda W`` (slides "Simulation: Chattering"), on an oblique or curved surface the
  frictionless motion along it, released where the constraint force vanishes;
* ``SLIDE``: Filippov sliding on switch ``didx`` with the convex field
  ``f12 = (1 - alpha) f_above + alpha f_below`` (thesis eq. 2.7-2.8) or Utkin's equivalent
  control ``f(t, x, u_eq)`` (slides; switch table column 4), optionally with the stabilising
  term ``-C h h_x^T`` of the slides; each accepted sliding step is projected back onto
  ``h = 0``;
* ``SLIDE_MULTI``: sliding on the intersection of ``k = 2 .. MULTI_MAX (10)`` Filippov
  surfaces; ``didx`` is the bit mask of their surface indices, ``mode`` the reference corner
  (the product variant above all of them; the other ``2^k - 1`` corners are reached from it
  across one surface at a time). The field is the multilinear extension of L. Dieci and
  L. Lopez (Numer. Math. 117 (2011) 779-811), ``f = sum_c prod_i w_i(c) f_c`` with
  ``w_i = lambda_i`` below surface ``i`` and ``1 - lambda_i`` above, ``lambda`` the root of
  ``h_i,t + h_i,x f = 0`` by Newton's method (``fields`` says why this rule: for
  fields affine in the signs it is the field at ``u_i = 1 - 2 lambda_i``, Utkin's
  equivalent control with a vector ``u``, the contacts' stick forces solved jointly); each
  accepted step is projected back onto every surface. For ``k = 1`` the rule is the convex
  combination, which stays ``SLIDE`` with its own code.

Switching surfaces
------------------
At the start, and after every reset, release or change of mode by an event, the mode is made
consistent with the side of every switching surface (:func:`_resolve`); a state on a Filippov
surface starts sliding if both fields point into it. An arrival at a surface crosses or starts
sliding according to the signs of ``h_t + h_x f`` of the two modes (thesis eq. 2.6-2.8);
switches of kind ``SW_CONTINUOUS`` (kinks of ``Abs``/``Max``/``Min``) always cross. Sliding
ends (``slide_end``) where ``hdot`` of the mode above turns positive (``alpha = 0``) or that of
the mode below turns negative (``alpha = 1``), located by Newton on that ``hdot``. Reaching
another switching surface while sliding is no event where the sliding motion only touches it
(its own rate on that surface points back: a tangential return, e.g. of a contact that slips
back to its stick speed exactly at its static bound while another sticks); otherwise it
crosses the surface if the sliding motion continues on its far side; if the sliding fields
on both sides point into it the motion slides on the intersection
(``slide_start``, ``SLIDE_MULTI``) where the multilinear weights lie in ``[0, 1]^k`` (an
attracting intersection), and the run ends with ``ST_INTERSECTION`` where they do not (or
more than ``MULTI_MAX`` surfaces would meet; :func:`intersection_cause` tells the message
which surface was reached and why). Sliding on an intersection ends on surface
``i`` (``slide_end``) where ``lambda_i`` reaches 0 (the motion leaves to the side above) or
1 (below); the other surfaces keep sliding as far as their own weights allow (on the rest of
the intersection, on one surface, or none: a released contact may make another slip at
once). A start on several Filippov surfaces is resolved the same way. The switches of a
sign family on one of its surfaces are a block of the switch table, and the switch of a
block that touches a mode is computed from the mode's index (the bit of the surface flipped),
not searched for: a chain of ten contacts has 5120 switches, and a search of them per lookup
cost more than the integration.

Watch functions
---------------
In each discrete state the kernel watches a small list of scalar functions of ``(t, x)`` for
zero crossings: surfaces ``h`` (events, switches), normal velocities ``hdot`` (sliding exit),
normal accelerations ``hddot`` (release from sticking) and ``min(lambda_i, 1 - lambda_i)`` of
the weights of sliding on an intersection (exit from one of its surfaces; the ``k`` watches of
an intersection share one solve of the weights per sample, kept in a small cache). On every accepted
step each is sampled on the dense output -- surfaces at the ends and at the interior extrema
of the cubic Hermite fit from ``h`` and ``hdot`` at the ends, the other functions at the ends
and the midpoint (the normal acceleration of a sticking motion also at the extrema of its
Hermite fit, its slopes by central differences). Where such a function has one sign at two
consecutive samples and an extremum towards zero between them (``hdot`` changes sign: near
grazing, a short release window), that extremum is searched for on the dense output -- the
exact flow on an exact step -- with a lower bound from the tangents at the bracket's ends
(:func:`_extremum_search`), so a crossing and re-crossing inside one step is found whenever
it is deeper than the dense output's error. The earliest crossing is bracketed and located
on the dense output to a few ulps -- by the Illinois method, or on an exact step (whose dense
output is the exact flow, with derivative ``h f``) for a surface of a regular mode by
safeguarded Newton with ``h`` and ``hdot`` from the model (``_locate_exact``) where the
crossing is resolved above round-off (near a graze Illinois keeps it) -- then the step is
re-taken exactly to that time ("landing step") and the time is polished with Newton steps on ``h`` (or
``hdot`` for a sliding exit) so the event state comes from the integrator itself, not from
the interpolant.
A surface that depends on ``t`` explicitly (a moving constraint) must also be resolved by the
step: where the Hermite fit misses ``h`` at the step's midpoint by more than 1% the step is
retaken shorter, so a state at rest cannot step over an oscillating wall.

A function that is zero at the start of a step fires at that time if the next sample lies on
the far side of the event direction, never otherwise. On the first step after a restart (the
start of the run, every event) a surface within its round-off band (:func:`_surface_offset`)
counts as zero, and its rate within its own band (:func:`_rate_band`) as tangency: a start on
a wall moving (or curving) into it, a sliding exit or release that ends on another surface,
is an event at that time whatever the sign of the round-off; a start on a surface moving away
is none. The same band decides after an event: a round-off normal velocity is not "moving
away", and after an impact with the free normal acceleration into the surface it is contact
(``STICK``).

Watch arrays are sized from the model (one entry per event and switch, plus spares), so any
number of events and switches per mode is watched.

Output
------
``opts.save``: ``SAVE_EVENTS`` stores the nodes on both sides of every event and the end
(sweeps); ``SAVE_DENSE`` every step with its power-form dense output; ``SAVE_NODES`` every
step with its length only -- the dense output is rebuilt when it is read by taking the step
again from its start node (:func:`dense_coefficients`: the same stages from the same numbers,
so the same coefficients), which costs the run nothing (storing it doubled the cost of a
Runge-Kutta run and added the three extra stages of DOP853's interpolant to every step).

Sampling
--------
With ``opts.sample_dt > 0`` the state at ``opts.sample_t0 + k opts.sample_dt`` is recorded from each
step's dense output as the integration passes it (stroboscopic sections: no event, no landing
step); across a chattering gap it is the linear interpolation the trajectory also uses.

Exact propagation
-----------------
With ``opts.exact`` the regular modes that are affine in the state with harmonic forcing
(:mod:`pwsdyn.model.affine`) are not integrated but propagated by the exact flow
``z(t + h) = exp(h M) z(t)`` of the state augmented with the forcing. Steps are limited to
``||h D^-1 M D||_inf <= 1`` (after scaling the constant and forcing columns; ``D`` balances
``M`` by powers of two, so a stiff spring's steps follow its frequency, not its stiffness:
:func:`_affine_setup`): a full step is one
product with a propagator made once per mode and run (:func:`_exact_propagator`), any other
step sums the Taylor series of the vector (:func:`_exact_step`), whose terms are the step's
dense output -- the exact flow, so the event search runs on it and the landing on an event
is its evaluation, the terms then rescaled to the shortened interval. Their error estimate
is zero, and they make no field at their end (the watch functions give their own rates;
nothing on the exact path reads it). Their event search skips the sample at an extremum
of the Hermite fit that lies beyond both ends of the step on the far side of the surface (the
bottom of a flight below a wall), where within the step bound no crossing can hide.
Sticking, sliding, non-affine modes and the variational equations stay on the Runge-Kutta
pair.

Termination
-----------
No input makes the kernel spin. Non-finite input (``t0``, ``t_end``, ``x0``, first step,
a NaN largest step, tolerances, sampling time or period) ends the run before any work with
``ST_NONFINITE``, as does a non-finite time, state or field at the start and after every
event (a NaN reset) or a step size that turns NaN. A Runge-Kutta stage or a watch function
that turns non-finite inside a step has the step retaken shorter, down to 4 ulp of ``t``:
the run ends with ``ST_NONFINITE`` at the last finite state. Accepted steps are counted
against ``max_steps`` and events against ``max_events``; a rejection shrinks the step by at
least 10% (an accepted step grows it at most 10x) and a step below 4 ulp of ``t`` ends the
run, so rejections are bounded too; samples are bounded by ``max_steps`` (more requested
ends the run at once with ``ST_MAX_STEPS``); inner loops (event location, Newton
polishing, projections, the equivalent control) have fixed iteration caps.

Time never passes ``t_end``: the last step ends at ``t_end`` exactly, and a complete-
chattering jump is taken only where its accumulation point lies within ``t_end``; before a
later one the impacts are integrated one by one, and where they fall below the velocity
floor (unresolvable) the run ends at ``t_end`` on the chord of the chattering gap.

Variational equations
---------------------
With ``variational`` the state is augmented by the n x n matrix ``Phi`` (row-major), integrated
with ``Phi' = J Phi`` and updated at every event by the full saltation matrix (slides,
"Saltation matrices"; Adolfsson et al. 2001) with the ``h_t`` and ``g_t`` terms of
time-dependent surfaces and resets: :func:`_event_saltation` (impacts, transitions),
:func:`_switch_saltation` (Filippov crossing, sliding entry), :func:`_chatter_saltation`
(complete chattering, the slides' ``G = C + (f_out - C f_in) h_x / (h_x f_in)`` with the time
derivatives of the map); entry into sliding on an intersection is the sliding entry formula
with ``f_in`` the sliding field before and ``f_out`` the multilinear one after, ``h`` the surface
reached; release, sliding exit and the exit from an intersection leave the field continuous
(at ``lambda_i = 0`` or 1 the multilinear field is that of the remaining surfaces: ``S = I``).
``J`` is symbolic in a regular mode and a central difference (step ~ eps^(1/3)) of the
sticking or sliding field (also on an intersection). Steps are accepted only when ``Phi``
meets the tolerances too.
With ``opts.variational == VAR_SEGMENTS`` ``Phi`` restarts at the identity after every event and
each event record carries the segment's ``Phi`` and ``S`` (the per-segment transfer matrices;
see :mod:`pwsdyn.integrate._variational`).
"""


from __future__ import annotations

from .actions import chatter_saltation, intersection_cause
from .fields import state_field
from .run import dense_coefficients, run_kernel
from .watch import GRAZING_RTOL

__all__ = ["GRAZING_RTOL", "chatter_saltation", "dense_coefficients", "intersection_cause",
           "run_kernel", "state_field"]
