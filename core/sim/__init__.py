"""Built-in vehicle–track simulator (docs/design.md §6): vehicle templates, track sections, wheel–rail
contact, the effect library and the numba-compiled integrator.

Public API::

    from railval.core.sim import VehicleModel, TrackSection, simulate_section, simulate_campaign, EFFECTS

The names load on first use (PEP 562 module ``__getattr__``): importing the light registries
(``railval.core.sim.effects``, ``railval.core.sim.vehicles``) does not compile or load the
numba integrator, so the command line can list effect ids without it (docs/app.md, start-up).
"""

from importlib import import_module

#: public name → submodule that defines it
_EXPORTS = {
    "EFFECTS": "effects", "EFFECT_IDS": "effects", "Effect": "effects", "get_effect": "effects",
    "resolve_effects": "effects",
    "channel_names": "model", "simulate_campaign": "model", "simulate_section": "model",
    "TrackSection": "track", "generate_irregularities": "track", "ore_b176_psd": "track",
    "TEMPLATES": "vehicles", "VehicleModel": "vehicles",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
