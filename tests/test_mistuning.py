"""Blade mistuning of a chain ([chain] mistuning = [delta_1, ...]): blade j's stiffness times
1 + delta_j, nothing else changed."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from slipstep.casefile.case import CASES_DIR, read_toml
from slipstep.errors import InputError
from slipstep.sweep.cases import build_case


def _K(system):
    K = system.structure.stiffness
    return np.asarray(K.toarray() if hasattr(K, "toarray") else K, float)


def test_a_mistuned_blade_has_its_stiffness_scaled_and_nothing_else():
    data = read_toml(CASES_DIR / "ring.toml")
    tuned, _ = build_case(data, str(CASES_DIR))
    mistuned = copy.deepcopy(data)
    deltas = [0.0, 0.05, 0.0, -0.03, 0.0, 0.0]
    mistuned["chain"]["mistuning"] = deltas
    system, _ = build_case(mistuned, str(CASES_DIR))
    names = system.structure.dof_names
    assert names == tuned.structure.dof_names
    Kt, Km = _K(tuned), _K(system)
    scale = np.ones(len(names))
    for j, d in enumerate(deltas):
        scale[[i for i, n in enumerate(names) if n.startswith(f"blade{j + 1}.")]] = 1.0 + d
    assert np.any(scale != 1.0)
    # blades couple to dampers through contacts only: K is block-diagonal over the blades
    np.testing.assert_allclose(Km, Kt * np.sqrt(np.outer(scale, scale)), rtol=1e-14, atol=0)
    np.testing.assert_array_equal(np.asarray(system.structure.mass), np.asarray(tuned.structure.mass))


@pytest.mark.parametrize("value", [[0.1, 0.0], [0.0, 0.0, -1.0, 0.0, 0.0, 0.0]])
def test_bad_mistuning_names_the_key(value):
    data = read_toml(CASES_DIR / "ring.toml")
    data["chain"]["mistuning"] = value
    with pytest.raises(InputError) as err:
        build_case(data, str(CASES_DIR))
    assert "chain.mistuning" in err.value.field
