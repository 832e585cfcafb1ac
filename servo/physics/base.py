"""What every physical effect module provides, and the small objects it is built from.

A module of :mod:`servo.physics` describes one physical effect of the drive and owns
everything about it in one :class:`Effect`, ``EFFECT``; adding an effect is that module
and its name in :data:`servo.physics.MODULES`.  The registry derives the config
sections, the record mappings, the diagnosis's vocabulary, the compensator's terms and
the docs tables from the modules.

**What an author writes** (the minimum, by what the effect is to do):

=====================================  ==============================================
the effect ...                         writes
=====================================  ==============================================
exists (the docs table)                ``Effect(name, doc)``
is carried by the simulated drive      ``drive`` its ``[drive]`` fields
                                       (:func:`servo.fields.P`: default, unit, doc,
                                       range) and ``plant(d, dt)`` the fields of
                                       :data:`kernels.plant.PLANT_PARAMS` it sets (the
                                       kernel's arithmetic reads them)
is named by ``servo diagnose``         ``term``: a :class:`Term` with ``name``,
                                       ``coefs``, ``units`` and ``full(design, theta,
                                       u_eff)`` its columns (n, k); a nonlinear one
                                       also ``thetas`` and ``grid(design, model)``.
                                       ``drive_map`` (:class:`DriveMap`: ``absent``,
                                       ``to_drive``, ``from_drive``) for the fitted
                                       model's ``[drive]`` fields
is hidden by the concealed study       ``study`` (:class:`Concealment`)
is cancelled by ``servo compensate``   ``compensator`` its fields, ``stage(c)`` the
                                       fields of :data:`kernels.stage.STAGE_PARAMS`
                                       it sets, ``cancel(d, how)`` its compensator
                                       term from a model's fields
                                       (:class:`Cancelling`), ``leave_out(d)`` the
                                       drive without it
cannot be cancelled                    ``not_cancellable``: why, and what to do
exerts a force at rest, changes the    ``rest_force(d, x)``, ``force_gain(d, x)``,
force constant, or sits on the input   ``command_for(d, u)`` (the holding current
                                       at start, :mod:`servo.runtime.simplant`)
makes a force the current limit must   ``forces(f, stroke, speed)`` (the model's
cover, or a rate of the rigid body     plausibility and the compensator's
                                       authority, :mod:`servo.compensate`),
                                       ``rates(f, J)``
=====================================  ==============================================

**What has defaults** (override only what the effect needs):

* :class:`Effect`: ``engaged`` (the stage's ``extras`` switch), ``simulated`` (its
  fields in the short-horizon simulation of a fitted model, default as fitted),
  ``diagnosed_by`` (a stage beside the selection rounds), ``renamed`` (former keys),
  and the force hooks ``rest_force``, ``force_gain``, ``command_for``, ``forces``,
  ``rates`` (None: no force at rest, a force constant of 1, the command as it is, no
  force, no rate).
* :class:`Term` is what a feature library has: ``name``, ``doc``, ``units``,
  ``coefs``, ``thetas``, ``full`` (the columns), ``grid`` and ``bounds`` (derived:
  ``rows`` through the rows' filter, ``physical`` / ``from_physical`` the same names,
  ``unit``).  The rest is three capabilities (:class:`Capability`), each a small
  object with defaults that are exact and always correct, which a term carries only
  to change one: ``path`` (:class:`SignalPath`: a column term of the measured motion
  by default; ``kind``, ``path_order``, ``transform``, ``idle``, ``column_design``,
  ...), ``search`` (:class:`Search`: ``requires``, ``gated``, ``eligible``, and the
  screening and refinement machinery's ``screen*``, ``coarse_*``, ``held``,
  ``refine_width``) and ``judging`` (:class:`Judging`: ``positive``,
  ``implausible``, ``implausible_on``, ``std_extra``, ``rests``, ``follows``, ...).
  A declared value is a keyword (``search = Search(requires=("offset",))``); a
  changed rule is a method of the term's own subclass, which reads the term as
  ``self.term``.  :class:`OneField` is a term that is one coefficient linear in the
  motion, :class:`OneFieldDrive` its drive map.
* :class:`DriveMap`: ``in_drive`` (whether a drive holds the term, from
  ``from_drive``), ``state`` (a hidden plant state the term holds, none).

The smallest named effect, the viscous friction (``servo/physics/viscous.py``)::

    class Viscous(OneField):
        name, coefs, units = "viscous_friction", ("B",), {"B": "F*s/m"}

        def full(self, d, theta, u_eff):
            return d.sig.vf

    EFFECT = Effect(
        "viscous_friction", "viscous friction B*x'",
        drive=dict(B=P(2.0e-3, "A*s/m", "viscous friction", 0.0)),
        compensator=dict(B=P(2.0e-3, "A*s/m", "viscous friction estimate", None, None)),
        plant=one_field("B"), stage=one_field("B"), term=Viscous(),
        drive_map=OneFieldDrive("viscous_friction", "B"), study=..., leave_out=zero("B"),
        cancel=lambda d, how: [(EQ9, {"B": number(d, "B")})],
    )

Forces are in the recording's (or the drive's) force unit ``F`` (A of VCM current, or N),
positions in m, times in s.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class Concealment:
    """How the concealed-effect study (:mod:`servo.diagnose.concealed`) hides a term in the
    null drive: the ``physics`` a diagnosis should name, the size's ``unit`` and meaning
    (``what``), the sizes of the detection study, a clearly detectable size for the tests,
    the baseline to diagnose with and drive fields ``fixed`` at every size."""

    physics: str
    unit: str
    what: str
    sizes: tuple
    clear: float
    baseline: str = "J,B,Fc,K,h0"
    fixed: dict = field(default_factory=dict)
    #: ``fields(size)``: the ``[drive]`` fields that put the effect into the null drive
    #: at ``size`` (beside ``fixed``)
    fields: Callable = lambda size: {}
    #: ``calibrate(log, size)``: for a size measured on the run itself, the ``[drive]``
    #: fields set from a first run's log (None: ``fields`` alone)
    calibrate: Callable | None = None

    def drive(self, size: float) -> dict:
        """The ``[drive]`` fields of the effect at ``size``."""
        return {**self.fixed, **self.fields(size)}


@dataclass(frozen=True)
class Effect:
    """One physical effect, as its module declares it (see module doc).

    ``name`` the effect's name (its diagnosis term's vocabulary name when it has one);
    ``doc`` one line for the docs table; ``drive``/``compensator`` its config fields,
    name -> :func:`servo.fields.P` field, in the order the sections list them;
    ``plant(d, dt) -> dict`` its :data:`~kernels.plant.PLANT_PARAMS` fields;
    ``stage(c) -> dict`` its :data:`~kernels.stage.STAGE_PARAMS` fields (an array field
    as a sequence filling its first entries); ``engaged(c) -> bool`` whether its
    compensator term is on (the stage's ``extras`` switch; None: not one of those);
    ``term`` its diagnosis term (None: the diagnosis does not name it, or names it
    from a module of its own, :func:`servo.physics.register_term`);
    ``drive_map`` the term's ``[drive]`` fields in a fitted model (:class:`DriveMap`);
    ``leave_out(d)`` sets the ``[drive]`` fields ``d`` (a dict) in place to what the drive
    holds without the term, so that a compensator leaves it out
    (:mod:`servo.compensate.significance`; None: not a compensator term);
    ``study`` how the concealed-effect study hides it (:class:`Concealment`);
    ``not_cancellable`` why no static compensator term cancels it ("" if one does);
    ``simulated(d, sim) -> dict`` its ``[drive]`` fields in the short-horizon simulation of a
    fitted model (:class:`Simulation`; None: as fitted, :meth:`simulation`);
    ``diagnosed_by`` the diagnosis stage beside the selection rounds that names its term
    (``"lattice"`` the sensor's lattice test, :mod:`servo.diagnose.quantization`;
    ``"breakaway"`` the test at rest, :mod:`servo.diagnose.breakaway`; ``"frf"`` the
    frequency response above the rows' band, :mod:`servo.diagnose.frf_modes`; "": the
    rounds alone);
    ``cancel(d, how) -> list[(name, keys)]`` its compensator term(s) for the drive fields
    ``d`` of a model (a dict): what each cancels and the ``[compensator]`` fields it
    sets (:class:`Cancelling`; entries of the same name from several effects are one
    term, their fields in registry order; None or ``[]``: none);
    ``renamed`` its config keys' former names, ``"section.old" -> "new"`` (a config that
    uses an old one is refused with the new name);
    ``rest_force(d, x) -> float`` the force (force unit) the effect exerts on the arm at
    rest at position ``x`` (m) of the drive section ``d``, its Dahl element relaxed (the
    holding current, :func:`servo.physics.rest_force`; None: none);
    ``force_gain(d, x) -> float`` the factor the effect puts on the force constant at
    ``x`` (None: 1);
    ``command_for(d, u) -> float`` the command whose force on the arm is ``u``, through
    an input element of the effect (None: ``u`` itself);
    ``forces(f, stroke, speed) -> {what: size}`` the largest ``|force|`` (force unit) the
    effect's fields ``f`` (a dict of either section's fields) make at positions up to
    ``stroke`` (m) and speeds up to ``speed`` (m/s; None: unknown, the forces that grow
    with speed left out), by what it is: entries of the same ``what`` from several effects
    add up (:func:`servo.physics.largest_forces`; None: none);
    ``rates(f, J) -> {what: rad/s}`` the rigid body's rates its fields ``f`` (either
    section's, a dict) make with the moving mass ``J`` (a pole, a natural frequency: a
    sampled loop cannot see one beyond its Nyquist frequency; None: none).  The fields in the force
    unit (converted with a force constant) are those whose declared unit is in ``A``
    (:func:`servo.physics.force_fields`)."""

    name: str
    doc: str
    drive: dict = field(default_factory=dict)
    compensator: dict = field(default_factory=dict)
    plant: Callable | None = None
    stage: Callable | None = None
    engaged: Callable | None = None
    term: "Term | None" = None
    not_cancellable: str = ""
    renamed: dict = field(default_factory=dict)
    drive_map: DriveMap | None = None
    leave_out: Callable | None = None
    study: Concealment | None = None
    simulated: Callable | None = None
    diagnosed_by: str = ""
    cancel: Callable | None = None
    rest_force: Callable | None = None
    force_gain: Callable | None = None
    command_for: Callable | None = None
    forces: Callable | None = None
    rates: Callable | None = None

    def simulation(self, d: dict, sim: "Simulation") -> dict:
        """The effect's ``[drive]`` fields in the short-horizon simulation of a fitted
        model whose fields are ``d`` (:meth:`servo.diagnose.fit.Fit.drive`): the
        ``simulated`` hook's, or else its fields as fitted."""
        if self.simulated is not None:
            return self.simulated(d, sim)
        return {k: d[k] for k in self.drive}


@dataclass(frozen=True)
class Cancelling:
    """How :mod:`servo.compensate.propose` asks each effect's ``cancel`` hook for its
    compensator term: ``paper`` what eq. (9) alone can hold (one sliding level, none of
    the terms beyond it: an effect beyond eq. 9 gives none); ``dahl_length`` (m) the
    Dahl element's to fold a Coulomb level into when the model has none."""

    paper: bool = False
    dahl_length: float = 3.125e-6


@dataclass(frozen=True)
class Simulation:
    """What the short-horizon simulation of a fitted model
    (:mod:`servo.diagnose.simulate`) tells each effect's ``simulated`` hook: ``P`` every
    term's reported parameters (:meth:`~servo.diagnose.fit.Fit.combined`), ``stroke``
    (m) stops the motion never reaches, ``u_scale`` the largest ``|u|`` of the recording
    (force unit, at least 1e-300).  The simulation applies the input terms to the input
    beforehand and steps the flexible modes apart: their fields are off in it."""

    P: dict
    stroke: float
    u_scale: float


class Capability:
    """A part of a term's interface beyond its columns that a term may carry, with
    defaults the pipeline applies without knowing the term (:class:`SignalPath`,
    :class:`Search`, :class:`Judging`).  A term carries one as a class attribute
    (``search = Search(requires=("offset",))``, or an instance of its own subclass that
    overrides a method); read through a term it is bound to it (``self.term``).  The
    keyword arguments set the capability's declared values (an unknown one is refused)."""

    term = None
    _attr = ""

    def __init__(self, **values):
        for k, v in values.items():
            if k.startswith("_") or not hasattr(type(self), k) or callable(getattr(type(self), k)):
                raise TypeError(f"{type(self).__name__}: no value {k!r} to set")
            setattr(self, k, v)

    def __set_name__(self, owner, name):
        self._attr = name

    def __get__(self, term, owner=None):
        if term is None:
            return self
        bound = copy.copy(self)
        bound.term = term
        term.__dict__[self._attr] = bound  # bound once per term (an instance attribute shadows this descriptor)
        return bound


class SignalPath(Capability):
    """Where a term sits on the signal path of the force balance (defaults: a column
    term of the measured motion).

    ``kind`` ``"column"``, ``"input"`` or ``"sensor"`` (:class:`Term`); ``uses_input``
    its columns read the effective input; ``signs_by_input`` its friction's sign is
    placed with it; ``path_order`` an input term's place on the input's path to the arm;
    ``transform`` an input term's change of the input; ``idle`` an input term that
    changes no row; ``column_design`` the signals other terms' columns read when the
    model holds this one; ``frf_param``/``frf_factor`` an input term's one parameter and
    factor on the frequency response (:mod:`servo.diagnose.frf_modes`)."""

    kind = "column"
    uses_input = False
    #: its columns switch with the motion's direction, whose reversals are placed with
    #: the effective input (:meth:`servo.diagnose.signals.Signals.sign_for`): its rows
    #: are cached per input, as ``uses_input``'s, but it is not an input-reading term
    signs_by_input = False
    #: an input term's place on the input's path to the arm (lower first, as in the drive)
    path_order = 0
    #: the parameter the frequency-domain path fits to an input term ("": none)
    frf_param = ""

    def transform(self, u: np.ndarray, theta: dict, dt: float) -> np.ndarray:
        """An input term's input reaching the arm (n,) from the recorded ``u`` (n,) at
        sample period ``dt`` (s) with parameters ``theta``."""
        raise NotImplementedError(f"{self.term.name}: a {self.kind} term has no transform of the input")

    def idle(self, params: dict, u: np.ndarray) -> bool:
        """Whether the term, with ``params``, leaves the recorded input ``u`` (n,) as it
        is (an input term that changes no row)."""
        return False

    def column_design(self, d, model, phys: "Term"):
        """The design whose signals the term ``phys``'s columns read when ``model`` holds
        this term (a sensor lag: the lag-corrected motion); None: the design ``d`` itself."""
        return None

    #: ``frf_factor(theta, f, dt)``: an input term's factor (k,) complex on the
    #: input-to-position response at ``f`` (k,) Hz (None: not on the frequency path)
    frf_factor = None


class Search(Capability):
    """What the selection (:mod:`servo.diagnose.select`) asks of a term beyond its grid
    and bounds: when it may be tried (``requires``, ``gated``, :meth:`eligible`), fast
    approximations for large grids and the final refinement's intervals.  The defaults
    are exact and always correct; a term overrides them for speed (``screen``,
    ``screen_batch``, ``screen_sums``, ``screen_target``, ``coarse_*``) or to refine its
    ``thetas`` between grid points (``held``, ``refine_width``)."""

    #: the terms a model must hold before this one is tried
    requires: tuple = ()
    #: whether the term may be present from some time on only (a mass does not appear
    #: half-way: :mod:`servo.diagnose.partial`)
    gated = True
    #: why the term is never tried on top of a model ("": it is, :meth:`eligible`)
    never = ""

    def eligible(self, model) -> str | None:
        """None when the term may be tried on top of ``model``, else why not."""
        t = self.term
        if self.never:
            return self.never
        if model.has_free(t.name) or (model.has(t.name) and t.thetas):
            return "already in the model"
        for r in self.requires:
            if not model.has(r):
                return f"needs {r} in the model first"
        return None

    @property
    def screening(self) -> bool:
        """Whether its large grids are scanned with fast approximate rows: it has its own
        :meth:`screen` (derived, not declared)."""
        return type(self).screen is not Search.screen

    def screen(self, d, theta: dict, model) -> np.ndarray:
        return d.variant_rows(self.term.name, theta, model)

    def screen_batch(self, d, thetas: list, model) -> np.ndarray:
        """Approximate rows of several variants at once, (J, k, m)."""
        return np.stack([np.atleast_2d(self.screen(d, th, model).T) for th in thetas], axis=0)

    def screen_sums(self, d, thetas: list, model, r: np.ndarray, blocks):
        """Screening sums ``(a, H)`` of all ``thetas`` at once, (K, J, k) and (K, J, k, k)
        as :func:`servo.diagnose.select.screen_stats` of :meth:`screen_batch`, computed
        without the columns (a compiled kernel); None: not available, the caller builds
        the columns in chunks."""
        return None

    def coarse_batch(self, d, thetas: list, model) -> np.ndarray | None:
        """Cheap approximate rows of several variants, (J, k, m), that rank them among
        themselves before their exact columns are built (the full-rate formula read at
        the rows' instants, without the rows' filter): the selection builds exactly only
        the variants each fold ranks near the top of those
        (:meth:`servo.diagnose.select.Selector.score`), and every variant
        :meth:`coarse_ranks` leaves out.  None (the default): every variant is built
        exactly."""
        return None

    def coarse_ranks(self, theta: dict) -> bool:
        """Whether :meth:`coarse_batch` ranks the variant ``theta`` faithfully among the
        others it says so of (the default: none; such a variant is always built exactly)."""
        return False

    def screen_target(self, d, model, theta: dict) -> np.ndarray | None:
        """An input term's target rows (m,) tried on top of ``model`` (which lacks the
        term), computed faster than the exact chain; None: use the exact chain."""
        return None

    def held(self, theta: dict) -> tuple:
        """The ``thetas`` the refinement keeps at the grid point ``theta``'s values (a
        part of the term the grid switched off); default none."""
        return ()

    def refine_width(self, d, name: str, value: float) -> float:
        """Half-width of the final refinement's interval around a grid point ``value`` of
        the linear-scale parameter ``name``: 15 % of the value."""
        return 0.15 * abs(value)


class Judging(Capability):
    """How the report judges and shows a fitted term (defaults: any sign, no derived
    parameter, held out as predicted): ``positive`` parameter -> what a negative value
    means (:meth:`note`); :meth:`implausible` why fitted parameters do not describe the
    physics (then it is not named); ``std_extra`` the std of derived reported
    parameters; ``rests``, ``follows``, :meth:`followed`, :meth:`proven` for a term
    that changes what the verdict's tests read."""

    #: parameter -> what a negative value means
    positive: dict = {}
    #: what :meth:`followed` does to the verdict's held-out residual, for its text ("": nothing)
    follows = ""
    #: why, with this term in the model, the arm's intervals at rest say nothing of a
    #: breakaway (:mod:`servo.diagnose.breakaway`; "": they do)
    rests = ""

    def note(self, params: dict) -> str:
        """A remark when a fitted parameter has a sign the physics does not expect."""
        for k, v in params.items():
            if k in self.positive and v < 0:
                return f"{k} < 0: {self.positive[k]}"
        return ""

    def implausible(self, params: dict) -> str:
        """Why fitted parameters (:meth:`Term.physical`) do not describe this physics (""
        if they do): then the term is not named, whatever the test said."""
        return ""

    def implausible_on(self, params: dict, d) -> str:
        """:meth:`implausible`, and why the parameters are beyond what the recording of
        design ``d`` resolves (a length below its position noise): "" if neither."""
        return self.implausible(params)

    def followed(self, d, theta: dict, r: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The verdict's held-out residual (m,) of a model holding this term, on the test
        ``rows``: as predicted (the default), or, for a term that is a record of the
        recording's past rather than a property of the drive (a wandering offset,
        :mod:`servo.physics.drift`), with its course through the test part fitted there,
        every other coefficient as trained (its proof: :meth:`proven`)."""
        return r

    def proven(self, d, theta: dict, r: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The held-out proof's residual (m,) of a model holding this term, on the test
        ``rows``: as predicted (the default); a term whose course no past forecasts (a
        wandering offset) has it cross-fitted on the test part, fitted on some of its
        rows and judged on the others (a drift: across the motion's direction), every
        other coefficient as trained."""
        return r

    def std_extra(self, params: dict, std: dict) -> dict:
        """Std of the derived reported parameters (``std`` holds the fitted ones')."""
        return {}


class Term:
    """A diagnosis term: what a feature library has (its name, doc, units, coefficients
    and nonlinear parameters, its columns, its grid and the refinement's bounds), and
    three capabilities with defaults: its place on the signal path (``path``,
    :class:`SignalPath`), what the selection asks beyond its grid (``search``,
    :class:`Search`) and how the report judges it (``judging``, :class:`Judging`); the
    base is a linear column term with no nonlinear parameter.

    ``name`` the vocabulary name (the effect's); ``coefs`` the coefficients the columns
    are linear in, ``thetas`` the nonlinear parameters fixed while they are fitted;
    ``units`` name -> unit (``F`` the force unit); ``doc`` one line;
    ``full(design, theta, u_eff)`` the full-rate columns (n, k) of the filtered motion
    (``design.sig``); ``grid(design, model)`` the ``theta`` a diagnosis tries (``[{}]``
    for a linear term); ``bounds(design, model)`` the refinement's interval per theta.
    Derived, overridden where the reported parameters are not the fitted ones:
    ``rows``, ``physical``/``from_physical`` (default: the same names), ``unit``.

    Each term contributes to the force balance ``u_eff = sum coef * column`` (see
    :mod:`servo.diagnose.model`) in one of three ways (``path.kind``):

    * ``column`` terms add regressor columns, linear in their coefficients ``coefs`` for
      fixed nonlinear parameters ``thetas`` (a Stribeck velocity, a Dahl length, a mode's
      frequency and damping, a cogging period).  The columns are built at full rate from
      the filtered motion and passed through the rows' parallel filter.
    * ``input`` terms transform the recorded input before it reaches the arm (a
      saturation level, a delay); they change the target, not the columns.
    * ``sensor`` terms (quantisation) change neither: see
      :mod:`servo.diagnose.quantization`.

    What the rest of the tool knows of the effect is not the term's: its ``[drive]``
    fields in a fitted model (:class:`DriveMap`), how a compensator leaves it out and
    how a study conceals it (:class:`Concealment`) are the effect module's other
    objects (:class:`Effect`)."""

    name = ""
    coefs: tuple = ()
    thetas: tuple = ()
    units: dict = {}
    doc = ""

    path = SignalPath()
    search = Search()
    judging = Judging()

    def full(self, d, theta: dict, u_eff: np.ndarray) -> np.ndarray:
        """Full-rate columns (n, k)."""
        raise NotImplementedError

    def grid(self, d, model) -> list:
        return [{}]

    def bounds(self, d, model) -> dict:
        """Refinement bounds per theta: name -> (lo, hi, log_scale)."""
        return {}

    def rows(self, d, theta: dict, u_eff: np.ndarray) -> np.ndarray:
        """The exact rows (m, k): :meth:`full` through the rows' parallel filter."""
        F = np.atleast_2d(self.full(d, theta, u_eff).T).T
        return np.column_stack([d.sig.rows(np.ascontiguousarray(F[:, j])) for j in range(F.shape[1])])

    def physical(self, theta: dict, coef) -> dict:
        """Reported parameters (name -> value)."""
        return {**dict(zip(self.coefs, map(float, coef))), **{k: float(v) for k, v in theta.items()}}

    def from_physical(self, p: dict) -> tuple[dict, tuple]:
        return {k: p[k] for k in self.thetas}, tuple(p[k] for k in self.coefs)

    def unit(self, name: str, force_unit: str) -> str:
        return self.units.get(name, "-").replace("F", force_unit)


#: the compensator term of eq. (9)'s viscous friction and bias (``B``, ``K``, ``h0``)
EQ9 = "viscous friction, bias (eq. 9)"

#: the ``forces`` hooks' names of the forces several effects add to
#: (:attr:`Effect.forces`): the forces that hold at rest over the stroke, the
#: friction of large motions, and the forces that grow with the speed
BIAS = "bias (the position forces at the stroke)"
SLIDING = "sliding friction level"
VISCOUS = "viscous force at the largest speed"


def number(d: dict, key: str, default: float = 0.0) -> float:
    """The field ``key`` of the fields ``d`` as a float (``default`` when it lacks it)."""
    return float(d.get(key, default))


def geom(lo: float, hi: float, per_decade: float) -> np.ndarray:
    """A geometric grid from ``lo`` to ``hi`` with about ``per_decade`` points a decade."""
    if not (hi > lo > 0):
        return np.zeros(0)
    k = max(2, int(math.ceil(math.log10(hi / lo) * per_decade)) + 1)
    return np.geomspace(lo, hi, k)


def contiguous(z) -> np.ndarray:
    """``z`` as a contiguous float64 array (what the kernels take)."""
    return np.ascontiguousarray(z, dtype=float)


def fold_ranges(blocks) -> tuple[np.ndarray, np.ndarray]:
    """Each fold's first and past-the-end row (K,), int64."""
    starts = np.array([sl.start for sl in blocks.slices], dtype=np.int64)
    stops = np.array([sl.stop for sl in blocks.slices], dtype=np.int64)
    return starts, stops


def valid_speed(d) -> np.ndarray:
    """The speeds (m/s) of the design's valid training rows."""
    s = d.sig
    m = d.train_valid if getattr(d, "train_valid", None) is not None else s.valid
    return np.abs(s.v_rows[m])


class OneField(Term):
    """A term that is one coefficient, linear in the motion: its columns of the measured
    motion obey a lagged force balance exactly (a sensor lag leaves them as they are,
    :mod:`servo.diagnose.sensor_lag`)."""


class DriveMap:
    """A term's fields in the simulated drive's ``[drive]`` section (``DriveConfig``):
    ``absent`` its fields when a model lacks the term; ``to_drive(P, fit)`` its fields
    (force unit, m, s) in a fitted model (``P`` is ``fit.combined()``, every term's
    reported parameters, ``fit`` the :class:`~servo.diagnose.fit.Fit`): the final model
    written as a config, its short-horizon simulation; ``from_drive(d)`` the term as a
    drive ``d`` has it, ``(theta, coef)`` pairs (fixed coefficients), ``[]`` when the
    drive lacks it: a drive config held as a model file; ``in_drive(d)`` whether it
    holds the term at all."""

    name = ""
    absent: dict = {}

    def to_drive(self, P: dict, fit) -> dict:
        return {}

    def from_drive(self, d) -> list:
        return []

    def in_drive(self, d) -> bool:
        return bool(self.from_drive(d))

    def state(self, design, theta: dict, P: dict, u: np.ndarray, record: np.ndarray) -> np.ndarray | None:
        """The plant's hidden state the term holds at every sample (n,) (the Dahl
        element's force), for a simulation started from the measured motion: the term
        with nonlinear parameters ``theta`` in a model whose reported parameters are
        ``P``, on the input ``u`` (n,) and the plant record ``record``; None: no state
        (it starts at 0)."""
        return None


class OneFieldDrive(DriveMap):
    """The drive map of a term whose one coefficient is the ``[drive]`` field ``key``."""

    def __init__(self, name: str, key: str):
        self.name, self.key, self.absent = name, key, {key: 0.0}

    def to_drive(self, P, fit):
        return {self.key: P[self.name][self.key]}

    def from_drive(self, d):
        return [({}, (getattr(d, self.key),))]


def field_at(key: str):
    """A concealment's ``fields``: the ``[drive]`` field ``key`` at the size."""
    return lambda size: {key: size}


def zero(key: str):
    """A ``leave_out``: the ``[drive]`` field ``key`` set to 0."""

    def leave_out(d: dict) -> None:
        d[key] = 0.0

    return leave_out


def one_field(name: str):
    """A plant or stage mapping that copies the section field ``name`` into the record
    field of the same name."""
    return lambda section, *_: {name: getattr(section, name)}


__all__ = ["BIAS", "EQ9", "SLIDING", "VISCOUS", "Cancelling", "Capability", "Concealment", "DriveMap", "Effect",
           "Judging", "Search", "SignalPath",
           "OneField", "OneFieldDrive", "Simulation", "Term", "contiguous", "field_at", "fold_ranges", "geom",
           "number", "one_field", "valid_speed", "zero"]  # fmt: skip
