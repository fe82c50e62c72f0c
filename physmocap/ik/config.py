"""One validated configuration for a retarget: targets, solver, planting, contacts.

:class:`RetargetConfig` groups the option objects of each stage, so every
option lives in exactly one place and means one thing:

* :class:`~physmocap.ik.targets.TargetOptions`: how targets fit the character
  (``scale_root``, ``source_floor``: the *actor's* floor in the source);
* :class:`~physmocap.ik.solver.SolverOptions`: the per-frame IK (``floor``:
  the *floor constraint* on or off, ``floor_height``: where it is);
* :class:`~physmocap.ik.planting.PlantOptions`: foot planting;
* :class:`~physmocap.ik.contacts.ContactOptions` and
  :class:`~physmocap.ik.body_contacts.BodyContactOptions`: contact detection.

Field names are unique across the stages, so flat keywords (what the
command line collects, ``retarget(motion, plant=False)``) map onto one field
each: :meth:`RetargetConfig.with_options` is the one place that does it, and
it refuses an unknown name.  Every option object validates its values when it
is made.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from ..errors import OptionError
from .body_contacts import BodyContactOptions
from .contacts import ContactOptions
from .planting import PlantOptions
from .solver import SolverOptions
from .targets import TargetOptions

__all__ = ["RetargetConfig"]

_STAGES = {"targets": TargetOptions, "solver": SolverOptions, "plant": PlantOptions}


@dataclass(frozen=True)
class RetargetConfig:
    """Everything that shapes a retarget, stage by stage (see the module docstring).

    Attributes:
        targets: Target building.
        solver: Per-frame IK.
        plant: Foot planting (``plant.plant=False`` retargets without contacts).
        contacts: Foot contact detection thresholds.
        body_contacts: Knee, hand and pelvis contact detection thresholds.
    """

    targets: TargetOptions = field(default_factory=TargetOptions)
    solver: SolverOptions = field(default_factory=SolverOptions)
    plant: PlantOptions = field(default_factory=PlantOptions)
    contacts: ContactOptions = field(default_factory=ContactOptions)
    body_contacts: BodyContactOptions = field(default_factory=BodyContactOptions)

    def __post_init__(self) -> None:
        for name, kind in (*_STAGES.items(), ("contacts", ContactOptions), ("body_contacts", BodyContactOptions)):
            if not isinstance(getattr(self, name), kind):
                raise OptionError(f"RetargetConfig.{name} must be a {kind.__name__}, got {type(getattr(self, name)).__name__}")

    @staticmethod
    def option_names() -> list[str]:
        """Every flat option name :meth:`with_options` accepts."""
        return sorted(f.name for kind in _STAGES.values() for f in dataclasses.fields(kind))

    def with_options(self, **options: Any) -> "RetargetConfig":
        """A copy with flat options applied, each to the stage that owns its name
        (``max_iterations=8``, ``floor=False``, ``plant=False``...).

        Raises:
            OptionError: For a name no stage has (the message lists the known ones),
                or a value the stage refuses.
        """
        changes: dict[str, dict[str, Any]] = {stage: {} for stage in _STAGES}
        unknown = []
        for key, value in options.items():
            for stage, kind in _STAGES.items():
                if key in {f.name for f in dataclasses.fields(kind)}:
                    changes[stage][key] = value
                    break
            else:
                unknown.append(key)
        if unknown:
            raise OptionError(f"unknown retarget option(s) {sorted(unknown)}; known options: {self.option_names()}")
        try:
            replaced = {stage: dataclasses.replace(getattr(self, stage), **c) for stage, c in changes.items() if c}
        except TypeError as exc:
            raise OptionError(f"bad retarget option: {exc}") from None
        return dataclasses.replace(self, **replaced)
