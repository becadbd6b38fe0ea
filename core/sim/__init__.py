"""Built-in vehicle–track simulator (docs/design.md §6): vehicle templates, track sections, wheel–rail
contact, the effect library and the numba-compiled integrator.

Public API::

    from railval.core.sim import VehicleModel, TrackSection, simulate_section, simulate_campaign, EFFECTS
"""

from railval.core.sim.effects import EFFECT_IDS, EFFECTS, Effect, get_effect, resolve_effects
from railval.core.sim.model import channel_names, simulate_campaign, simulate_section
from railval.core.sim.track import TrackSection, generate_irregularities, ore_b176_psd
from railval.core.sim.vehicles import TEMPLATES, VehicleModel

__all__ = [
           "EFFECTS",
           "EFFECT_IDS",
           "TEMPLATES",
           "Effect",
           "TrackSection",
           "VehicleModel",
           "channel_names",
           "generate_irregularities",
           "get_effect",
           "ore_b176_psd",
           "resolve_effects",
           "simulate_campaign",
           "simulate_section",
]
