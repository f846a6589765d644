"""Post-processing of result Datasets: energy balance, steady state and last period,
hysteresis loops with dissipated energy and equivalent stiffness/damping, contact-state
timeline, resampling, and the paper's a posteriori low-pass filter."""

from slipstep.post.energy import energy_balance, external_force, friction_energy_per_period
from slipstep.post.filtering import (
    CutOff,
    FilterWarning,
    choose_cutoff,
    excitation_frequencies,
    filter_dataset,
    lowest_internal_frequency,
    lowpass,
    state_frequencies,
    visited_states,
)
from slipstep.post.loops import (
    contact_loops,
    interface_loops,
    interfaces_from_system,
    loop_energy,
    loop_properties,
    loop_summary,
)
from slipstep.post.periodic import Periodicity, last_period, period_of, periodicity
from slipstep.post.timeline import (
    change_times,
    count_state_changes,
    debounce,
    full_slip_share,
    is_uniform,
    resample_uniform,
    state_segments,
    state_shares,
    states_from_forces,
)

__all__ = [
    "CutOff",
    "FilterWarning",
    "Periodicity",
    "change_times",
    "choose_cutoff",
    "contact_loops",
    "count_state_changes",
    "debounce",
    "energy_balance",
    "excitation_frequencies",
    "external_force",
    "filter_dataset",
    "friction_energy_per_period",
    "full_slip_share",
    "interface_loops",
    "interfaces_from_system",
    "is_uniform",
    "last_period",
    "loop_energy",
    "loop_properties",
    "loop_summary",
    "lowest_internal_frequency",
    "lowpass",
    "period_of",
    "periodicity",
    "resample_uniform",
    "state_frequencies",
    "state_segments",
    "state_shares",
    "states_from_forces",
    "visited_states",
]
