r"""The registry of reducers: what each says of itself, and how the suite finds them.

**Registration by presence.** Every package (folder with an ``__init__.py``) under
``morsuite/reducers/`` is a *family* (``irka``, ``h2``, ``bt``, ``modal``, ``krylov``, ...).
On the first call of :func:`available`, :func:`get_class`, :func:`make`, :func:`describe` or
:func:`methods`, every module of every family is imported (:mod:`pkgutil`) and every
:class:`~morsuite.reducers.base.Reducer` subclass that declares both ``name`` and
``DESCRIPTION`` in its own class body is registered under its ``name``; its family is the
folder it lives in. So a new method is one folder (and its test and doc page): nothing
else names it. Abstract bases (``IRKABase``, ``SquareRootBT``) declare no description
and are not registered. Reducers outside the package register through the entry-point
group ``morsuite.reducers`` (``name = "module:Class"`` in the plugin's pyproject), or
by calling :func:`register`.

**A reducer describes itself** in a :class:`Description` (class attribute
``DESCRIPTION``): its label, the kind of reduced model, what it targets, its cost in
sparse LUs, what to use it for, the few options users set (the rest have defaults or
live in advanced groups), and named :class:`Variant`\ s (``bt-vv`` is ``bt`` with
``form="vv"``). :func:`methods` lists every reducer and every variant as a
:class:`Method` (reducer, options, label, first-order states per order): the methods
that ``morsuite compare``, the stress runner, the benchmarks and the docs' reducer
table offer, read from here. Cost of the discovery: importing the reducers' modules
(about a second, once per process); nothing else.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import warnings
from dataclasses import dataclass, field
from types import MappingProxyType

from ..errors import OptionError

__all__ = ["Description", "Variant", "Method", "register", "available", "get_class", "make", "describe", "methods",
           "method", "families", "RESULTS", "GRAMIAN_USE"]

#: the kinds of reduced model a reducer returns (``Description.result``)
RESULTS = ("second-order", "first-order", "by-option")
#: how a reducer uses the model's LR-ADI Gramian factors (``Description.gramians``): it reads them
#: ("reads"), it reads them only when it does not converge ("waits"), or not at all (None)
GRAMIAN_USE = (None, "reads", "waits")


@dataclass(frozen=True)
class Variant:
    """A named setting of a reducer's options offered as a method of its own.

    ``name`` (e.g. ``"bt-vv"``), the ``options`` it sets (``{"form": "vv"}``), its ``label``
    (a legend) and ``order`` (its place in the lists of methods, as :class:`Description`'s).
    Plain data; validated against the reducer's option table by :func:`methods`.
    """

    name: str
    options: dict
    label: str
    order: int = 1000


@dataclass(frozen=True)
class Description:
    """What a reducer says of itself (the class attribute ``DESCRIPTION`` of a registered reducer).

    Parameters
    ----------
    label : str
        Legend label of the method at its defaults (e.g. ``"IRKA (paper, second-order)"``).
    result : str
        The reduced model: ``"second-order"`` (order r, 2r first-order states),
        ``"first-order"`` (r states) or ``"by-option"`` (decided by an option: the class
        overrides :meth:`~morsuite.reducers.base.Reducer.states_for`).
    targets : str
        What the method targets, one line (the reducer table's column).
    cost : str
        Its cost in sparse LUs, one line.
    use_for : str
        What to use it for, one line.
    options : tuple of str
        The options users set; every other option has a default that serves (or sits in an
        advanced group) and is listed in the option reference only.
    variants : tuple of Variant
        Named settings offered as methods of their own (``bt-vv``).
    default : bool
        Among the methods ``morsuite compare`` runs when none are named (its variants: see
        ``default_variants``).
    default_variants : tuple of str
        The variants among compare's defaults.
    band_option : str or None
        The option that takes the comparison's frequency band (``"band"`` for ``bt-fl``):
        ``morsuite compare`` sets it to the band it compares on.
    gramians : str or None
        One of :data:`GRAMIAN_USE`: whether the method reads the model's LR-ADI Gramian
        factors (the batch scheduler starts it after the unit that computes them).
    stress : dict or None
        Options in the stress runner's ``reduce`` family (an iteration cap, a quadrature
        cap); None: not one of the methods drawn there (:mod:`morsuite.stress.cases`).
    page : str
        The design page under ``docs/design/`` (without ``.md``); default the reducer's name
        with ``-`` as ``_``.
    order : int
        Its place in the lists of methods (compare's defaults and its help, the reducer table):
        lower first, then by name (default 1000: after the methods of the package).
    family : str
        The folder under ``morsuite/reducers/`` (set by the discovery; plugins: their package).
    """

    label: str
    result: str
    targets: str = ""
    cost: str = ""
    use_for: str = ""
    options: tuple = ()
    variants: tuple = ()
    default: bool = False
    default_variants: tuple = ()
    band_option: str | None = None
    gramians: str | None = None
    stress: dict | None = None
    page: str = ""
    order: int = 1000
    family: str = ""

    def __post_init__(self):
        if self.result not in RESULTS:
            raise OptionError(f"Description.result must be one of {', '.join(RESULTS)}; got {self.result!r}")
        if self.gramians not in GRAMIAN_USE:
            raise OptionError(f"Description.gramians must be one of {GRAMIAN_USE}; got {self.gramians!r}")
        object.__setattr__(self, "options", tuple(self.options))
        object.__setattr__(self, "variants", tuple(self.variants))
        object.__setattr__(self, "default_variants", tuple(self.default_variants))
        if self.stress is not None:
            object.__setattr__(self, "stress", MappingProxyType(dict(self.stress)))


@dataclass(frozen=True)
class Method:
    """One method as compare, benches and the docs offer it: a registered ``reducer`` with ``options``.

    ``name`` is the reducer's name or a variant's; ``label`` its legend; ``states_per_order``
    the first-order states per unit of r (2: second-order result); ``result`` the kind of
    reduced model; ``description`` the reducer's :class:`Description`; ``order`` its place in lists.
    """

    name: str
    reducer: str
    options: dict
    label: str
    states_per_order: int
    result: str
    description: Description = field(repr=False)
    order: int = 1000

    @property
    def default(self) -> bool:
        """Among ``morsuite compare``'s default methods."""
        d = self.description
        return d.default if self.name == self.reducer else self.name in d.default_variants


# -- the registry ----------------------------------------------------------
_REGISTRY: dict[str, type] = {}
_FAMILY: dict[str, str] = {}
_DISCOVERED = False
_ENTRY_POINTS_LOADED = False


def register(name: str, cls, family: str | None = None):
    """Register reducer class ``cls`` under ``name`` (``family``: its folder; default its package's last part).

    The package's reducers need no call (they register by presence); plugins register
    through the entry-point group ``morsuite.reducers`` or call this. Returns ``cls``.
    """
    _REGISTRY[name] = cls
    _FAMILY[name] = family or cls.__module__.split(".")[-2 if cls.__module__.count(".") else -1]
    return cls


def families() -> list[str]:
    """The family folders under ``morsuite/reducers/`` (sorted). Cost: a directory listing."""
    path = sys.modules[__package__].__path__  # the package's (not imported here: no import circle)
    return sorted(m.name for m in pkgutil.iter_modules(path) if m.ispkg)


def _declares(obj) -> bool:
    """A reducer class (duck-typed: ``OPTIONS`` and ``reduce``; the registry does not import the base
    class) that declares ``name`` and ``DESCRIPTION`` in its own body."""
    return (isinstance(obj, type) and "name" in vars(obj) and "DESCRIPTION" in vars(obj)
            and hasattr(obj, "OPTIONS") and callable(getattr(obj, "reduce", None)))


def _discover():
    """Import every module of every family and register the reducers they define (once per process)."""
    global _DISCOVERED
    if _DISCOVERED:
        return
    _DISCOVERED = True
    try:
        for fam in families():
            pkg = importlib.import_module(f"{__package__}.{fam}")
            mods = [pkg] + [importlib.import_module(m.name)
                            for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")]
            for mod in mods:
                for obj in vars(mod).values():
                    if _declares(obj) and obj.__module__ == mod.__name__:
                        if obj.name in _REGISTRY and _REGISTRY[obj.name] is not obj:
                            raise OptionError(f"reducer name {obj.name!r} is declared twice: by "
                                              f"{_REGISTRY[obj.name].__module__} and {obj.__module__}")
                        register(obj.name, obj, fam)
    except BaseException:
        _DISCOVERED = False  # a family that fails to import is said on every call, not hidden after the first
        raise


def _load_entry_points():
    global _ENTRY_POINTS_LOADED
    if _ENTRY_POINTS_LOADED:
        return
    _ENTRY_POINTS_LOADED = True
    from importlib.metadata import entry_points

    for ep in entry_points(group="morsuite.reducers"):
        if ep.name not in _REGISTRY:
            try:
                cls = ep.load()
            except Exception as exc:  # a broken plug-in must not break the suite
                warnings.warn(f"reducer entry point {ep.name!r} failed to load: {exc}")
                continue
            register(ep.name, cls)


def _load():
    _discover()
    _load_entry_points()


def available() -> list[str]:
    """Names of the registered reducers (the package's families and the entry-point plugins), sorted."""
    _load()
    return sorted(_REGISTRY)


def get_class(name: str):
    """The reducer class registered as ``name`` (also from ``morsuite.reducers`` entry points).

    Raises
    ------
    OptionError
        If no reducer has that name; the message lists the available ones.
    """
    _load()
    if name not in _REGISTRY:
        raise OptionError(f"unknown reducer {name!r}; available: {', '.join(available())}")
    return _REGISTRY[name]


def make(name: str, fom, **options):
    """Construct reducer ``name`` bound to ``fom`` with ``options``."""
    return get_class(name)(fom, **options)


def describe(name: str) -> Description:
    """The :class:`Description` of reducer ``name``, its ``family`` filled in.

    A class without a ``DESCRIPTION`` of its own (a plugin, a subclass) gets one derived from what it
    has: its name as label, the kind of result from :meth:`~morsuite.reducers.base.Reducer.states_for` at its
    defaults, no variants. Cost: none after the discovery.
    """
    from dataclasses import replace

    cls = get_class(name)
    desc = vars(cls).get("DESCRIPTION")  # its own: a subclass does not inherit its parent's variants
    if not isinstance(desc, Description):
        spo = cls.states_for(_defaults(cls))
        desc = Description(label=name, result="second-order" if spo == 2 else "first-order")
    return replace(desc, family=desc.family or _FAMILY.get(name, ""), page=desc.page or name.replace("-", "_"))


def _defaults(cls) -> dict:
    return {k: opt.default for k, opt in cls.OPTIONS.items()}


def _full_options(cls, options: dict, where: str) -> dict:
    from .options import expand_options

    try:
        flat, _ = expand_options(cls.__name__, cls.OPTIONS, getattr(cls, "GROUPS", {}), options)
    except OptionError as exc:
        raise OptionError(f"{where}: {exc}") from exc
    return {k: opt.validate(cls.__name__, k, flat.get(k, opt.default)) for k, opt in cls.OPTIONS.items()}


def methods() -> dict[str, Method]:
    """Every registered reducer at its defaults and every variant, by name, in their declared ``order``
    (then by name).

    Raises
    ------
    OptionError
        If a variant's name is taken (by a reducer or another variant) or sets an option its
        reducer does not declare or a value outside the option's constraint.
    """
    out: dict[str, Method] = {}
    for name in available():
        cls, desc = get_class(name), describe(name)
        spo = cls.states_for(_full_options(cls, {}, f"reducer {name!r}"))
        out[name] = Method(name, name, {}, desc.label, spo, _result(spo, desc), desc, desc.order)
    for name in available():
        cls, desc = get_class(name), describe(name)
        for v in desc.variants:
            if v.name in out:
                raise OptionError(f"variant {v.name!r} of reducer {name!r}: the name is taken by "
                                  f"{'reducer' if v.name in _REGISTRY else 'another variant'} {v.name!r}")
            spo = cls.states_for(_full_options(cls, dict(v.options), f"variant {v.name!r}"))
            out[v.name] = Method(v.name, name, dict(v.options), v.label, spo, _result(spo, desc), desc, v.order)
    return dict(sorted(out.items(), key=lambda kv: (kv[1].order, kv[0])))


def _result(spo: int, desc: Description) -> str:
    return desc.result if desc.result != "by-option" else ("second-order" if spo == 2 else "first-order")


def method(name: str) -> Method:
    """The :class:`Method` called ``name`` (a reducer or a variant).

    Raises
    ------
    OptionError
        If there is none; the message lists the valid names.
    """
    ms = methods()
    if name not in ms:
        raise OptionError(f"unknown method {name!r}; valid: {', '.join(ms)}")
    return ms[name]

