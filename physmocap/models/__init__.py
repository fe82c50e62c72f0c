"""Characters: MJCF models plus a mapping of canonical joints onto their sites and bodies.

Public API::

    from physmocap.models import load_character, Character, TrackedFrame

    ch = load_character()                      # default humanoid (assets/mjcf/humanoid.xml)
    ch = load_character("robot")               # a bundled character by name
    ch = load_character("my.xml", "my.map.toml")

* :mod:`~physmocap.models.character`: :class:`Character`, :func:`load_character`.
* :mod:`~physmocap.models.mapping`: the TOML mapping file format.
* :mod:`~physmocap.models.anthropometry`: body proportions and masses (Winter 2009).
* :mod:`~physmocap.models.rom`: range-of-motion table (goniometry) and its policies.
* :mod:`~physmocap.models.velocity`: peak joint speeds (biomechanics literature).
* :mod:`~physmocap.models.humanoid_builder`: generates ``assets/mjcf/humanoid.xml``.
* :mod:`~physmocap.models.geometry`: geom extents, lowest and highest points.
* :mod:`~physmocap.models.footprint`: heel and toe points found on the feet's geometry.
* :mod:`~physmocap.models.propose`: a mapping proposed for a humanoid MJCF from its names and
  tree (``physmocap character init``).
"""

from .character import DEFAULT_CHARACTER, Character, bundled_characters, load_character
from .mapping import TrackedFrame

__all__ = ["Character", "TrackedFrame", "load_character", "bundled_characters", "DEFAULT_CHARACTER"]
