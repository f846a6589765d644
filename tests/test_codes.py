"""One table of codes (kernels/codes.py): the kernels' status integers are errors.Status, the
contact-state codes are the ones results, post, advise and plots name and the schema states,
and every contact law of the model has a kernel code."""

import re

import numpy as np

import slipstep as ss
from docs_pages import gen_pages
import importlib

from slipstep.post import plots
from slipstep.errors import Status
from slipstep.kernels import codes
from slipstep.model.contact import CONTACT_LAWS
from slipstep.post import timeline

from slipstep.output.results import SCHEMA

advise = importlib.import_module("slipstep.study.advise")


def _contact_laws_section() -> str:
    """The contact-law section of the site's case-file page (docs/gen_pages.py renders it)."""
    page = gen_pages().case_file_reference()
    return page.split("## Contact laws")[1].split("\n## ")[0]


def test_status_codes_are_the_status_enum():
    kernel = {name: getattr(codes, name) for name in Status.__members__}
    assert kernel == {name: int(member) for name, member in Status.__members__.items()}


def test_state_codes_named_once_and_stated_in_the_schema():
    states = [codes.LIFT, codes.STICK, codes.SLIP_POS, codes.SLIP_NEG, codes.SLIP_COUPLED]
    assert states == list(range(len(codes.STATE_NAMES)))
    text = SCHEMA["contact_state"][2]
    assert re.findall(r"(\d) ([\w+-]+)", text) == [(str(i), n) for i, n in enumerate(codes.STATE_NAMES)]
    assert timeline.STATE_NAMES is codes.STATE_NAMES and advise.STATE_NAMES is codes.STATE_NAMES
    assert len(plots.STATE_COLORS) == len(codes.STATE_NAMES)
    assert set(codes.SLIP_STATES) == {codes.SLIP_POS, codes.SLIP_NEG, codes.SLIP_COUPLED}


def test_result_flags_and_law_coordinate():
    ds = ss.run(ss.load_system("paper"), "quasi-static", periods=0.2)
    attrs = ds.contact_state.attrs
    assert list(attrs["flag_values"]) == list(range(len(codes.STATE_NAMES)))
    assert len(attrs["flag_meanings"].split()) == len(codes.STATE_NAMES)
    assert list(ds.contact_law.values) == ["2d"] * ds.sizes["contact"]
    assert np.all(ds.contact_state.values < len(codes.STATE_NAMES))


def test_every_law_has_a_kernel_code_and_a_row_on_the_case_file_page():
    assert {law.code for law in CONTACT_LAWS.values()} == {codes.LAW_UNCOUPLED, codes.LAW_CIRCLE}
    rows = dict(re.findall(r"^\| `([\w-]+)` \| [^|]* \| ([^|]+) \|", _contact_laws_section(), flags=re.M))
    assert {name: law.bounds for name, law in CONTACT_LAWS.items()} == {k: v.strip() for k, v in rows.items()}
