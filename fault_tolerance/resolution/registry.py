"""The resolvers by name: one :class:`ResolverEntry` per resolver, registered once.

A resolver is one module (its reference rates, equation-tagged, and its options dataclass) plus one
entry here. Everything that names resolvers (``ft.resolve``, ``ft.Controller``, ``ft.simulate``,
``ft.batch.resolve``, the CLI, the plots and the replay page) asks this registry, so a resolver
registered from outside the package (a test, a user's module) runs everywhere the built-ins do:

    >>> import numpy as np, fault_tolerance as ft
    >>> from fault_tolerance.resolution import registry
    >>> "jvja" in registry.names() and registry.get("jvja").bounded is not None
    True

The built-ins (LNVA, JVJA, MDA) register themselves in :mod:`fault_tolerance.resolution.resolvers`,
which ``import fault_tolerance`` loads. Whole-path planners (``"global"``) are not step resolvers:
they register into :data:`fault_tolerance.simulation.simulate.PATH_PLANNERS`.

Keywords of a call are of two kinds. *Context* (:data:`CONTEXT`) is what the caller knows about
the call, not a choice of the user: ``proj`` (the projection of ``J``), ``tolerate`` (damp
near-intolerable pivots), ``joint_names``, and ``arm``/``q`` (the configuration, for resolvers
that need it) or what the caller computed from it already: ``dJ`` (the Jacobian derivatives) and
``M`` (the joint-space inertia M(q)). A resolver gets the context its ``rates`` signature names and ignores the
rest. Everything else is an *option*, validated by the entry's options dataclass: an option it
does not know raises :class:`~fault_tolerance.errors.InvalidInput` naming the allowed ones.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.checks import finite

#: Keywords a caller passes as context, not as the resolver's options (see the module doc).
CONTEXT = frozenset({"proj", "tolerate", "joint_names", "arm", "q", "dJ", "M"})
#: Context computed from the configuration: a resolver that takes one needs no ``arm`` and ``q``.
DERIVED = ("dJ", "M")

#: Modes of the toolkit's compiled kernels (control/fast, simulation/fast) a built-in runs on.
KERNEL_LNVA, KERNEL_JVJA, KERNEL_MDA = 0, 1, 2


@dataclass(frozen=True)
class ResolverEntry:
    """One resolver: its rates, its options, its bounded variant, how plots name it.

    Attributes:
        name: The name users type (``ft.resolve(name, ...)``, ``--algorithms``); lower case.
        rates: The reference rates ``rates(J, xdot, lockable, **context, **options) -> qd`` (n,).
        options: A frozen dataclass type of the resolver's options (fields with defaults), built
            from the keywords of a call; it validates their values in ``__post_init__``.
        bounded: ``bounded(J, xdot, lockable, lo, hi, **context, **options)`` returning a
            :class:`~fault_tolerance.resolution.bounded.BoundedRates` (rates inside the box
            ``[lo, hi]``), or None: then a bounded use (``bounds=``, ``limits=True``) raises.
        compiled: The mode of the toolkit's compiled kernels that compute this resolver
            (:data:`KERNEL_LNVA`, ...), or None: the Controller and the simulation run ``rates``
            (and ``bounded``) through their generic path.
        label: Legend text of the plots and the replay page.
        colour: Its colour there (``#rrggbb``).
        needs_configuration: ``rates`` needs ``arm`` and ``q`` (or what it takes of
            :data:`DERIVED`), as MDA (``dJ``) and jvja_inertia (``M``) do.
        description: One line for ``--help`` and the docs.
    """

    name: str
    rates: Callable[..., np.ndarray]
    options: type
    bounded: Callable | None = None
    compiled: int | None = None
    label: str = ""
    colour: str = "#7f7f7f"
    needs_configuration: bool = False
    description: str = ""
    context: frozenset = field(default=frozenset(), compare=False)

    def __post_init__(self) -> None:
        if not (isinstance(self.name, str) and self.name.isidentifier() and self.name.islower()):
            raise InvalidInput(
                f"resolver name {self.name!r} must be a lower-case identifier (e.g. 'damped_lnva')"
            )
        if not callable(self.rates):
            raise InvalidInput(f"resolver '{self.name}': rates must be callable")
        if not (dataclasses.is_dataclass(self.options) and isinstance(self.options, type)):
            raise InvalidInput(f"resolver '{self.name}': options must be a dataclass type")
        if not self.options.__dataclass_params__.frozen:  # type: ignore[attr-defined]
            raise InvalidInput(f"resolver '{self.name}': its options dataclass must be frozen")
        if self.bounded is not None and not callable(self.bounded):
            raise InvalidInput(f"resolver '{self.name}': bounded must be callable or None")
        if not self.label:
            object.__setattr__(self, "label", self.name.upper())
        object.__setattr__(self, "context", CONTEXT & _keywords(self.rates))

    @property
    def option_names(self) -> tuple[str, ...]:
        """The options this resolver takes, in the order of its dataclass."""
        return tuple(f.name for f in dataclasses.fields(self.options))

    def make_options(self, options: Mapping | None = None, **more):
        """The options dataclass from keywords, or :class:`InvalidInput` naming the allowed ones."""
        given = {**(options or {}), **more}
        unknown = sorted(set(given) - set(self.option_names))
        if unknown:
            raise InvalidInput(
                f"resolver '{self.name}': unknown option(s) {unknown}; its options are "
                f"{list(self.option_names)}"
            )
        return self.options(**given)

    def options_with(
        self, options: Mapping | None, run: Mapping, owned: Mapping | None = None
    ) -> dict:
        """Every option of this resolver by name: ``options``, then ``run``'s of the same name.

        ``run`` holds a caller's own settings that some resolvers take as options (a simulation's
        ``response`` and ``gain``, a Controller's ``gain`` and ``max_step``); an option this
        resolver does not take raises :class:`InvalidInput`, before any work. ``owned`` maps the
        options the caller sets itself (and may not take from ``options``) to the keyword to use.
        """
        given, owned = dict(options or {}), owned or {}
        clash = sorted(set(given) & set(owned))
        if clash:
            raise InvalidInput(
                f"option(s) {clash} of resolver '{self.name}' are set by "
                f"{[owned[k] for k in clash]} here, not by options="
            )
        self.make_options(given)  # unknown names and bad values raise here
        given.update({k: v for k, v in run.items() if k in self.option_names and k not in given})
        return _fields(self.make_options(given))

    def call(self, J, xdot, lockable=None, **keywords) -> np.ndarray:
        """``rates`` with the context it takes and the validated options (see the module doc)."""
        context, options = split(keywords)
        opts = self.make_options(options)
        derived = [k for k in DERIVED if k in self.context]
        if self.needs_configuration and all(context.get(k) is None for k in derived):
            if context.get("arm") is None or context.get("q") is None:
                alternatives = "".join(f" (or {k}=...)" for k in derived)
                raise InvalidInput(
                    f"{self.name} needs the configuration: pass arm=... and q=...{alternatives}"
                )
        own = {k: v for k, v in context.items() if k in self.context}
        return self.rates(J, xdot, lockable, **own, **_fields(opts))

    def call_bounded(self, J, xdot, lockable, lo, hi, **keywords):
        """``bounded`` with the context it takes and the validated options, or InvalidInput."""
        if self.bounded is None:
            raise InvalidInput(
                f"resolver '{self.name}' has no bounded variant: it cannot honour joint limits "
                "(bounds=None, limits=False, --no-limits); bounded resolvers: "
                f"{[n for n in names() if get(n).bounded is not None]}"
            )
        context, options = split(keywords)
        opts = self.make_options(options)
        own = {k: v for k, v in context.items() if k in CONTEXT & _keywords(self.bounded)}
        return self.bounded(J, xdot, lockable, lo, hi, **own, **_fields(opts))


_REGISTRY: dict[str, ResolverEntry] = {}


def _keywords(f: Callable) -> frozenset:
    return frozenset(inspect.signature(f).parameters)


def _fields(opts) -> dict:
    return {f.name: getattr(opts, f.name) for f in dataclasses.fields(opts)}


def split(keywords: Mapping) -> tuple[dict, dict]:
    """``(context, options)`` of a call's keywords (:data:`CONTEXT` and the rest)."""
    context = {k: v for k, v in keywords.items() if k in CONTEXT}
    if context.get("arm") is not None and not context.get("joint_names"):
        context["joint_names"] = context["arm"].joint_names  # lockable joints by name
    return context, {k: v for k, v in keywords.items() if k not in CONTEXT}


def register(entry: ResolverEntry, *, replace: bool = False) -> ResolverEntry:
    """Add ``entry`` under its name (``replace=True`` to overwrite one); returns it."""
    if not isinstance(entry, ResolverEntry):
        raise InvalidInput(f"register takes a ResolverEntry, got {type(entry).__name__}")
    if entry.name in _REGISTRY and not replace:
        raise InvalidInput(
            f"resolver '{entry.name}' is registered already; pass replace=True to overwrite it"
        )
    _REGISTRY[entry.name] = entry
    return entry


def unregister(name: str) -> ResolverEntry:
    """Remove the resolver ``name`` and return its entry (unknown name: InvalidInput)."""
    entry = get(name)
    del _REGISTRY[name]
    return entry


def get(name: str) -> ResolverEntry:
    """The entry of resolver ``name``, or :class:`InvalidInput` listing the registered names."""
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise InvalidInput(f"resolver {name!r} is not one of {sorted(_REGISTRY)}") from None


def names() -> tuple[str, ...]:
    """The registered resolvers, in the order they were registered."""
    return tuple(_REGISTRY)


def check_task(J, xdot) -> tuple[np.ndarray, np.ndarray]:
    """``J`` (m, n) and ``ẋ`` (m,) as finite float arrays, or :class:`InvalidInput`."""
    J = np.asarray(J, dtype=float)
    xdot = np.asarray(xdot, dtype=float)
    if J.ndim != 2 or xdot.shape != (J.shape[0],):
        raise InvalidInput(f"J must be (m, n) and xdot (m,); got {J.shape} and {xdot.shape}")
    return finite(J, "J"), finite(xdot, "xdot")
