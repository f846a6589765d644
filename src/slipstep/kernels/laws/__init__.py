"""Contact laws: one module per law. A law module gives the tangential part of the law as
small scalar functions (no arrays: numba inlines them into the contact loop of
:mod:`slipstep.kernels.contact` at no cost, which functions taking arrays in a loop do not
get), for one direction (uncoupled) or one contact (coupled), in contact (v > 0), with the
friction limit mu N given:

* ``law``         the return mapping: T, w_new and the state from u and w_old;
* ``linear``      the piecewise-linear form T = K_i(S) q + s_i(S, w_old) of a postulated state
                  S (a state without one, the coupled slip, evaluates the law's force);
* ``compatible``  does S satisfy its row of the state table at q (within a tolerance)?
* ``tangent``     the local stiffness entries dT/du, dT/dv: K_i(S), or the consistent
                  tangent of the return mapping where it is not piecewise constant.

The normal part is shared: N = k_n v, lift-off (T = N = 0, w = u) for v <= 0.
kernels/contact.py loops over the contacts, reads the law parameters (codes.P_KN, P_MU) and
dispatches on the law code. Adding a law: a module here with these four functions, a code
in codes.py (and, if its states are new, a state code and its name in STATE_NAMES), one
branch per function in contact.py (law, piecewise_law, compatible, contact_stiffness,
delta_stiffness), a name in slipstep.model.contact.CONTACT_LAWS, its row in the README.
"""
