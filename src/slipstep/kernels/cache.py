"""A fixed-capacity hash table from a contact-state key (int8 vector) to a slot index.

Factorisations and T_min are stored per slot by the caller, so each distinct state is
factorised once per run (there are at most 4^nd of them, and far fewer are visited).
Open addressing with linear probing; when the table is full the home slot is reused.
"""

from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def _hash(key):
    h = 1469598103934665603
    for i in range(key.shape[0]):
        h = (h ^ (key[i] + 7)) * 1099511628211
    return h


@njit(cache=True, nogil=True, error_model="numpy")
def find_slot(keys, used, key):
    """Return (slot, found). If not found, ``slot`` is where the key has been written
    (and ``used[slot]`` set); the caller must then fill the slot's data."""
    cap = keys.shape[0]
    home = _hash(key) % cap
    if home < 0:
        home += cap
    for probe in range(cap):
        s = (home + probe) % cap
        if not used[s]:
            for i in range(key.shape[0]):
                keys[s, i] = key[i]
            used[s] = True
            return s, False
        same = True
        for i in range(key.shape[0]):
            if keys[s, i] != key[i]:
                same = False
                break
        if same:
            return s, True
    for i in range(key.shape[0]):
        keys[home, i] = key[i]
    return home, False
