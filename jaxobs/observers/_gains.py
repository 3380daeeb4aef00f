"""Gains as fields with metadata: :func:`gain_metadata` marks one (``eqx.field(metadata=gain_metadata(...))``, or
:func:`gain` in one call), :func:`gain_fields` lists a class's.

A gain is an array field of an observer that a tuner may change.  Its metadata travels with the field, so a
study's NetCDF variable, a tuning job's bounds and the C export's comments all read one record
(:class:`GainInfo`):

- ``units``: CF/UDUNITS, e.g. ``"1"``, ``"rad s-1"``, ``"rad2 s-2"``;
- ``role``: the part of the observer the gain belongs to (``"sogi"``, ``"prefilter"``, ``"fll"``, ``"pll"``,
  ``"leso"``, ``"filter"``, ``"flux"``: the reduced-order flux observer's flux gain);
- ``bounds``: the open interval the constructor accepts, (lower, upper);
- ``long_name``: what it is, in words;
- ``symbol``: the paper's symbol, with the paper ("001: λ").

One check enforces every gain's declared ``bounds``: :func:`check_gains`, which
:class:`~jaxobs.observers.AbstractObserver` runs after every constructor (``__check_init__``).  A constructor
converts a gain (``as_float``) and leaves its range to that check; it checks by hand only what is not a gain
(a machine's Rs, a sample time, an initial speed).

A closed form is a design: :class:`ClosedForm` is the observer a paper's rule gives (the one the simulator
runs) with its inputs and its rows (:class:`DesignRow`: name, value, units, formula, source equation).  The
convention every observer class that a paper tunes follows:

- ``closed_form_design(**inputs, **constructor_keywords) -> ClosedForm`` is the one place the rule is
  evaluated; its keyword defaults are the paper's (``jaxobs.papers``), and ``ClosedForm.inputs`` lists the
  inputs it used (what ``jaxobs closed-form`` offers as options);
- ``closed_form(**kw)`` is ``closed_form_design(**kw).observer``, for the callers that want the observer;
- each row of a gain takes its units from the gain's :class:`GainInfo` (:func:`gain_row`); a quantity that is
  no field (a C-LESO's l1, l2 of 002 eq 16, the WIF's phase margin) is a :class:`DesignRow` of its own;
- formulas and sources live in the rows, not in the registry or the command line, which print them as
  they are.

Names follow the papers (001's k, k1, k2, λ; 000's K1, K2; 002's ω0, k1, k2, K_r, ωc), so one name may denote
different gains in two families (001's WIF k1 and 002's FA-LESO k1): a gain is (class, name), and its
:class:`GainInfo` says which it is.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import equinox as eqx
from jax.typing import ArrayLike

from ..core.validate import check_real

__all__ = [
    "GainInfo",
    "gain",
    "gain_metadata",
    "gain_fields",
    "gain_table",
    "check_gains",
    "DesignRow",
    "ClosedForm",
    "gain_row",
]

_KEY = "jaxobs_gain"


class GainInfo(NamedTuple):
    """A gain's metadata (module doc).

    Attributes:
        name: The field's name.
        units: Its UDUNITS units.
        role: The part of the observer the gain belongs to (``"sogi"``, ``"fll"``, ``"pll"``, ...).
        bounds: The open interval (lower, upper) of valid values.
        long_name: What it is.
        symbol: The paper's symbol (``"001: λ"``).
    """

    name: str
    units: str
    role: str
    bounds: tuple[float, float]
    long_name: str
    symbol: str


def gain_metadata(
    *, units: str, role: str, long_name: str, symbol: str, bounds: tuple[float, float] = (0.0, math.inf)
) -> dict[str, Any]:
    """The metadata that makes an observer field a gain: ``k: jax.Array = eqx.field(metadata=gain_metadata(...))``.

    The observers of jaxobs declare their gains in that form, which a type checker reads as a field without a
    default (``eqx.field`` is a dataclass field specifier; a call to :func:`gain` looks like a default value).

    Args:
        units: CF/UDUNITS units (``"1"`` when dimensionless).
        role: the part of the observer the gain belongs to.
        long_name: what the gain is, in words.
        symbol: the paper's symbol and the paper, e.g. ``"001: λ"``.
        bounds: the open interval (lower, upper) of valid values.

    Returns:
        The field's metadata: its :class:`GainInfo` record under the key :func:`gain_fields` reads.
    """
    return {_KEY: dict(units=units, role=role, bounds=tuple(bounds), long_name=long_name, symbol=symbol)}


def kp_pll_metadata() -> dict[str, Any]:
    """The metadata of a PLL's proportional gain ``kp_pll`` (the flux observers' and the LESOs' PLL).

    Returns:
        The field's metadata (:func:`gain_metadata`).
    """
    return gain_metadata(units="s-1", role="pll", long_name="PLL proportional gain", symbol="k_p (ours: 2ζω_b)")


def ki_pll_metadata() -> dict[str, Any]:
    """The metadata of a PLL's integral gain ``ki_pll`` (the flux observers' and the LESOs' PLL).

    Returns:
        The field's metadata (:func:`gain_metadata`).
    """
    return gain_metadata(units="s-2", role="pll", long_name="PLL integral gain", symbol="k_i (ours: ω_b²)")


def gain(
    *,
    units: str,
    role: str,
    long_name: str,
    symbol: str,
    bounds: tuple[float, float] = (0.0, math.inf),
    **kwargs: Any,
) -> Any:
    """An observer field that is a gain: ``eqx.field`` with its :class:`GainInfo` in the field's metadata.

    The same field as ``eqx.field(metadata=gain_metadata(...), **kwargs)``, in one call.

    Args:
        units: CF/UDUNITS units (``"1"`` when dimensionless).
        role: the part of the observer the gain belongs to.
        long_name: what the gain is, in words.
        symbol: the paper's symbol and the paper, e.g. ``"001: λ"``.
        bounds: the open interval (lower, upper) of valid values.
        **kwargs: passed to :func:`equinox.field`.

    Returns:
        A dataclass field for the observer's class body.
    """
    meta = gain_metadata(units=units, role=role, long_name=long_name, symbol=symbol, bounds=bounds)
    return eqx.field(metadata={**kwargs.pop("metadata", {}), **meta}, **kwargs)


def gain_fields(cls: type | eqx.Module) -> dict[str, GainInfo]:
    """The gains of an observer class (or instance), in field order, each with its :class:`GainInfo`.

    Args:
        cls: an observer class or an instance of one.

    Returns:
        name -> :class:`GainInfo` for every field declared with :func:`gain`.
    """
    cls = cls if isinstance(cls, type) else type(cls)
    if not dataclasses.is_dataclass(cls):
        return {}
    return {f.name: GainInfo(name=f.name, **f.metadata[_KEY]) for f in dataclasses.fields(cls) if _KEY in f.metadata}


def gain_table(designs: dict) -> dict[str, GainInfo]:
    """The gains of several designs (name -> observer), each name once, in the order they first appear.

    A study writes one variable per gain name, with that gain's units; every design that has a gain of that
    name must give it the same units.

    Args:
        designs: design name -> observer.

    Returns:
        gain name -> the :class:`GainInfo` of its first design.

    Raises:
        ValueError: two designs' gains of one name with different units.
    """
    table, owner = {}, {}
    for dname, obs in designs.items():
        for g, info in gain_fields(obs).items():
            if g not in table:
                table[g], owner[g] = info, dname
            elif table[g].units != info.units:
                raise ValueError(
                    f"designs: gain {g} is in {table[g].units!r} in design {owner[g]!r} and in {info.units!r} in "
                    f"{dname!r} ({type(obs).__name__}); a study's designs must give one gain name one unit"
                )
    return table


def check_gains(obs: eqx.Module) -> None:
    """Check every gain of ``obs`` against its declared bounds (its :class:`GainInfo`): the one bound check.

    Traced values (an observer built inside ``vmap`` or ``grad``) pass through, as in every constructor check
    (:mod:`jaxobs.core.validate`).

    Args:
        obs: An observer instance.

    Raises:
        ValueError: A gain outside its open interval, naming the class, the gain and the range.
    """
    owner = type(obs).__name__
    for name, info in gain_fields(obs).items():
        lo, hi = info.bounds
        check_real(name, getattr(obs, name), lower=lo, upper=None if math.isinf(hi) else hi, owner=owner)


class DesignRow(NamedTuple):
    """One row of a closed-form design.

    Attributes:
        name: The gain's field name, or the quantity's name (``"l1"``, ``"phase_margin_deg"``).
        value: Its value (a float or a JAX scalar: a design may be built from traced inputs).
        units: CF/UDUNITS units (``"1"`` when dimensionless).
        formula: The rule, in the paper's symbols (``"λ = 2ωc²/b"``).
        source: The paper and equation (``"001 eq (34)"``).
    """

    name: str
    value: Any
    units: str
    formula: str
    source: str


class ClosedForm(NamedTuple):
    """A closed-form design: the observer a paper's rule gives, with its inputs and rows (module doc).

    Attributes:
        observer: The observer the simulator runs.
        inputs: The rule's inputs, name -> value (the paper's defaults unless given).
        rows: The design's :class:`DesignRow` s, gains first.
        source: The paper's equations and table, in one line (what a tuning result records).
    """

    observer: Any
    inputs: dict
    rows: tuple
    source: str

    @property
    def rule(self) -> str:
        """The source and every row's formula, in one line (the C export's source line)."""
        return f"{self.source}: " + "; ".join(r.formula for r in self.rows)


def gain_row(cls: type, name: str, value: ArrayLike, formula: str, source: str) -> DesignRow:
    """The :class:`DesignRow` of gain ``name`` of ``cls``, in the units its :class:`GainInfo` declares.

    Args:
        cls: The observer class.
        name: The gain's field name.
        value: Its value.
        formula: The rule.
        source: The paper and equation.

    Returns:
        The row.

    Raises:
        KeyError: ``name`` is not a gain of ``cls``.
    """
    return DesignRow(name, value, gain_fields(cls)[name].units, formula, source)
