"""One colour per method everywhere; joints from a palette no method uses.

The matplotlib figures (:mod:`fault_tolerance.figures.runs`, ``.design``) and the replay page
(:mod:`fault_tolerance.viz.charts`) take every colour from here, so a method has one colour in every
picture and a joint's curve never looks like a method's:

    >>> from fault_tolerance.figures import colors
    >>> import fault_tolerance  # registers the built-in resolvers
    >>> colors.method_colour("jvja") == "#d62728" and colors.joint_colour(1) not in colors.method_colours().values()
    True

A method's colour is its registry entry's (``ResolverEntry.colour``; a path planner's from
``simulation.simulate.PATH_PLANNER_STYLES``). :func:`method_colours` keeps one colour per method: a
method whose colour an earlier method (in registration order) or a joint already has, e.g. a user's
resolver left at the default grey, gets the next free colour of :data:`SPARE_METHOD_COLOURS`.
Several runs of one method (the lock at the largest and at the smallest jump) share its colour and
differ in dash pattern (:data:`DASHES`). Pure Python: no matplotlib here.
"""

from __future__ import annotations

#: Colours of the joints (rates, torques, the parts of λ): none is a method's colour.
JOINT_COLOURS = (
    "#bcbd22",  # olive
    "#8c564b",  # brown
    "#393b79",  # indigo
    "#7f7f7f",  # grey
    "#e377c2",  # pink, not early: the lock is marked magenta
    "#637939",  # moss
    "#843c39",  # rust
    "#8c6d31",  # ochre
    "#7b4173",  # plum
    "#17becf",  # cyan, last: the replay page's tool trace is teal
)
#: Colours for methods whose registered colour is taken (by a method or a joint) or unknown.
SPARE_METHOD_COLOURS = (
    "#ff7f0e",
    "#000000",
    "#08519c",
    "#a50f15",
    "#006d2c",
    "#54278f",
    "#fd8d3c",
    "#e7298a",
)
#: Dash patterns of the 1st, 2nd, ... run of one method: (matplotlib linestyle, SVG dasharray).
DASHES = (("-", ""), ("--", "7 3"), ("-.", "7 2 2 2"), (":", "2 2"))


def _registered() -> dict[str, str | None]:
    """Every method by name, in registration order (step resolvers, then path planners)."""
    from fault_tolerance.resolution.registry import get, names
    from fault_tolerance.simulation.simulate import PATH_PLANNER_STYLES

    out: dict[str, str | None] = {n: get(n).colour for n in names()}
    out.update({n: style[0] for n, style in PATH_PLANNER_STYLES.items()})
    return out


def method_colours() -> dict[str, str]:
    """``{method: colour}`` for every registered method, one distinct colour each (module doc)."""
    taken = {c.lower() for c in JOINT_COLOURS}
    out: dict[str, str] = {}
    for name, colour in _registered().items():
        c = (colour or "").lower()
        if not c or c in taken:
            c = next((s for s in SPARE_METHOD_COLOURS if s not in taken), "#000000")
        out[name] = c
        taken.add(c)
    return out


def method_colour(name: str | None) -> str | None:
    """The colour of method ``name`` (any case), or None when no such method is registered."""
    return method_colours().get(str(name or "").lower())


def joint_colour(j: int) -> str:
    """The colour of the ``j``-th joint (0-based, cycling)."""
    return JOINT_COLOURS[j % len(JOINT_COLOURS)]


def run_styles(algorithms) -> list[tuple[str, int]]:
    """``(colour, dash index)`` per run: its method's colour; the k-th run of one method dash k.

    A run of no registered method gets a spare colour no method has (per such run).
    """
    known = method_colours()
    spare = [c for c in SPARE_METHOD_COLOURS if c not in known.values()] or ["#000000"]
    seen: dict[str, int] = {}
    out = []
    for i, algorithm in enumerate(algorithms):
        colour = known.get(str(algorithm or "").lower()) or spare[i % len(spare)]
        k = seen.get(colour, 0)
        seen[colour] = k + 1
        out.append((colour, k % len(DASHES)))
    return out
