"""Built-in vehicle–track simulator (DESIGN §6): vehicle templates, track sections, wheel–rail
contact, the effect library and the numba-compiled integrator.

Public API::

    from core.sim import VehicleModel, TrackSection, simulate_section, simulate_campaign, EFFECTS
"""

from core.sim.effects import EFFECT_IDS, EFFECTS, Effect, get_effect, resolve_effects
from core.sim.model import channel_names, simulate_campaign, simulate_section
from core.sim.track import TrackSection, generate_irregularities, ore_b176_psd
from core.sim.vehicles import TEMPLATES, VehicleModel

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
