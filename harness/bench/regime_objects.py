"""Objects for the regime sweep (``gpis-harness bench regimes``): 24 procedural objects
(:mod:`harness.procedural`: four of each family, one of them held out), written at each
regime's size and density, with a thickness of 0.3 times the size, jaw friction 0.5 and
the library's sensor noise (0.5 cells)."""

from __future__ import annotations

from harness.procedural import FAMILIES, ProceduralObject, make

#: The objects' own seed (not the experiment's: the objects are part of the benchmark).
OBJECT_SEED = 20261125
#: The prism's thickness over the object's size (3.3 cm at 11 cm).
THICKNESS_OVER_SIZE = 0.3


class RegimeObject(ProceduralObject):
    """An object of the sweep: written at a regime's size and density."""

    def scene_text(self, size: float, density: float) -> str:
        header = (f"# Regime sweep object: family {self.family}, number {self.index} "
                  f"({'held out' if self.held_out else 'design'}); written by gpis-harness bench regimes.")
        return super().scene_text(size, density, THICKNESS_OVER_SIZE * size, header=header)


def objects(per_family: int = 4, held_out_every: int = 4, families=FAMILIES, first: int = 0) -> list[RegimeObject]:
    """``per_family`` objects of each family, numbered from ``first``; in each family,
    every ``held_out_every``-th object (numbers 3, 7, ...) is held out: kept aside from
    every choice made on the sweep, and reported separately. An object depends on its
    family and number only, so objects with other numbers are other shapes."""
    out = []
    for family in families:
        for k in range(first, first + per_family):
            o = make(family, k, OBJECT_SEED, held_out=(k + 1) % held_out_every == 0)
            out.append(RegimeObject(o.name, o.family, o.index, o.shape, o.regions, o.held_out))
    return out


#: The numbers of the fresh objects (:func:`fresh_objects`): the four after the sweep's.
FRESH_FIRST = 4


def fresh_objects(per_family: int = 4, families=FAMILIES) -> list[RegimeObject]:
    """A second set of the sweep's families, numbers 4-7 of each (other shapes than the
    sweep's 0-3), every one held out: made after the lift model and the planners were
    settled, to test their range on objects nothing was ever looked at on
    (``gpis-harness bench regimes --objects fresh``)."""
    return objects(per_family, held_out_every=1, families=families, first=FRESH_FIRST)


#: The object sets ``bench regimes --objects`` takes.
OBJECT_SETS = {"sweep": objects, "fresh": fresh_objects}
