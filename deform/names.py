"""Names and defaults of the deformation stage as plain Python data: the five kinds and their
parameters, and the defaults of deforming by degree. No numpy, no scipy: the `breastplan`
command builds its options and help from them without loading the stage (docs/cli.md).
"""

KIND_PARAMS: dict[str, tuple[str, ...]] = {
    "top-shape": ("s0", "s1", "t0", "t1"),
    "flatten-side": ("h0", "h1"),
    "turn-top": ("g0", "g1"),
    "ptosis": ("b0", "b1"),
    "turn": ("c0", "c1"),
}
"""Parameter names of each kind, in the order the kinds are applied (docs/model.md §3)."""
DEFORMATION_PARAMS: tuple[str, ...] = tuple(n for kind in KIND_PARAMS.values() for n in kind)
"""The twelve deformation parameters in a deformation vector's order (s0 s1 t0 t1 h0 h1 g0 g1 b0 b1 c0 c1)."""
NEEDS_PRIMITIVE = frozenset({"top-shape", "flatten-side", "turn-top"})
"""Kinds whose formulas need the breast's primitive."""

DD = 8
"""Degrees of the shipped models and of `deform --degree` (thesis: 8)."""
DEFAULT_CONDITION = {"ptosis": "ptosis b0>b1", "turn": "turn c0>c1", "top-shape": "top-shape s1->s0+"}
"""The condition `deform --degree` follows for each kind when none is given."""
METHODS = ("exact", "learnt")
"""How `deform --degree` finds the parameters: the inverse solver or the shipped regressions."""

PLAUSIBLE = {"s0": (-4.0, 4.0), "s1": (-10.0, 4.0), "t0": (-8.0, 8.0), "t1": (-8.0, 2.0),
             "h0": (-0.5, 0.5), "h1": (-0.5, 0.5), "g0": (-1.0, 1.0), "g1": (-1.0, 1.0),
             "b0": (-1.0, 3.0), "b1": (-0.5, 1.0), "c0": (-1.5, 1.5), "c1": (-1.0, 1.0)}
"""The range a fit may give each deformation parameter (model units): what the thesis's breast
shapes and deformation conditions span, with a margin (docs/model.md §4, §6). t0 (β″(0), which
barely moves the surface) is wide: free fits of database breasts put it anywhere up to 6.8."""


def at_bounds(params: dict[str, float]) -> list[str]:
    """The parameters of `params` (name → value, model units) at an end of their PLAUSIBLE range: the
    fitted shape asked for more than the thesis's breasts ever do, so the model holds it only roughly."""
    return [n for n, (lo, hi) in PLAUSIBLE.items() if n in params and min(params[n] - lo, hi - params[n]) < 1e-6]
