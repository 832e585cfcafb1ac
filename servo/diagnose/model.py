"""A model held against a recording: a list of physical terms, and the rows it makes.

A :class:`Term` is one piece of physics from the vocabulary (:mod:`servo.diagnose.terms`)
with its nonlinear parameters ``theta`` fixed (a Stribeck velocity, a Dahl length, a
mode's frequency and damping, a delay...) and its linear coefficients either free
(fitted by least squares on the rows) or fixed (a model file held against the data).
The force balance is always

    u_eff = sum over column terms of coef * column(theta)          (one row per sample)

where ``u_eff`` is the recorded input after the model's *input* terms (saturation, then
delay, as in the drive) and the columns are functions of the filtered motion (and of
``u_eff`` for a position-dependent gain or a resonance).  :class:`Design` turns a model
into rows: the target (aligned, filtered, decimated ``u_eff`` minus the fixed terms) and
the matrix of free columns; it caches the columns, since a diagnosis asks for the same
ones many times, up to :data:`ROWS_BUDGET` bytes (the least recently used dropped and
computed again when asked for, to the bit).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from servo.diagnose.signals import Signals
from servo.diagnose.terms import VOCABULARY


@dataclass(frozen=True)
class Term:
    """One term of a model: ``physics`` (a vocabulary name), ``theta`` its nonlinear
    parameters as sorted ``(name, value)`` pairs, ``coef`` its fixed linear
    coefficients or None when they are free."""

    physics: str
    theta: tuple = ()
    coef: tuple | None = None

    @classmethod
    def make(cls, physics: str, theta: dict | None = None, coef=None) -> "Term":
        th = tuple(sorted((k, float(v)) for k, v in (theta or {}).items()))
        return cls(physics, th, None if coef is None else tuple(float(c) for c in coef))

    @property
    def params(self) -> dict:
        return dict(self.theta)

    @property
    def free(self) -> bool:
        return self.coef is None


@dataclass
class Model:
    """An ordered list of terms (baseline first, then what a diagnosis added)."""

    terms: list = field(default_factory=list)

    def has(self, physics: str) -> bool:
        return any(t.physics == physics for t in self.terms)

    def has_free(self, physics: str) -> bool:
        return any(t.physics == physics and t.free for t in self.terms)

    def get(self, physics: str) -> Term | None:
        for t in self.terms:
            if t.physics == physics:
                return t
        return None

    def plus(self, term: Term) -> "Model":
        return Model(self.terms + [term])

    def without(self, physics: str) -> "Model":
        return Model([t for t in self.terms if t.physics != physics])

    def corrects(self, physics: str) -> bool:
        """Whether a free ``physics`` term added to this model is a *correction* of a
        fixed term of a model file: the model holds ``physics`` only fixed, and it is a
        column term with linear coefficients only (``B +0.0008``)."""
        from servo.diagnose.terms import VOCABULARY

        phys = VOCABULARY[physics]
        fixed = any(t.physics == physics and not t.free for t in self.terms)
        return fixed and not self.has_free(physics) and phys.path.kind == "column" and not phys.thetas

    def refitted(self, keep: str | None = None) -> "Model":
        """The model as a diagnosis fits it once anything is tried on or added to a model
        file: the linear coefficients of every fixed column term made free (the file's
        values are the reference the corrections are reported against and the model
        judged before any finding, not a constraint), except the terms of ``keep`` and
        those with a free term of their physics beside them (a correction, which carries
        the change).  Nonlinear parameters (a Dahl length, a mode's frequency) and input
        terms stay as the file has them.  A model without fixed terms is returned as is."""
        from servo.diagnose.terms import VOCABULARY

        if all(t.free for t in self.terms):
            return self
        free = {t.physics for t in self.terms if t.free}
        out = []
        for t in self.terms:
            if not t.free and VOCABULARY[t.physics].path.kind == "column" and t.physics != keep and t.physics not in free:
                t = Term(t.physics, t.theta, None)
            out.append(t)
        return Model(out)

    def input_terms(self) -> list:
        return [t for t in self.terms if VOCABULARY[t.physics].path.kind == "input"]

    def column_terms(self) -> list:
        return [t for t in self.terms if VOCABULARY[t.physics].path.kind == "column"]


#: the parameter of a term gated in time: its onset (s), the term's columns are zero
#: before it (:meth:`Design.term_rows`; searched by :mod:`servo.diagnose.partial`)
GATE = "from_s"

#: full-rate effective inputs a :class:`Design` keeps (each is ``8*n`` bytes)
U_CACHE = 2

#: bytes of cached rows a :class:`Design` keeps; beyond it some are dropped (and
#: computed again if asked for: :meth:`Design.cached_rows`).  A diagnosis of 1e6 samples
#: caches about 130 MB of rows (3e6: about 390 MB), so below 4e6 samples nothing is
#: dropped and nothing is computed twice; at 1e7 the cache would be 1.3 GB, most of it
#: the rows of the variants a round scores once and the next round scores again
ROWS_BUDGET = 512 * 2**20


class Design:
    """Rows of models on one recording's :class:`Signals`, with a column cache."""

    def __init__(self, sig: Signals, train_rows: np.ndarray | None = None):
        self.sig = sig
        #: (m,) rows of the training part; ``train_valid`` those usable by fits
        self.train_rows = np.ones(sig.m, bool) if train_rows is None else np.asarray(train_rows, bool)
        self.train_valid = self.train_rows & sig.valid
        #: (n,) full-rate samples up to the last training row
        last = sig.keep[np.flatnonzero(self.train_rows)[-1]] if self.train_rows.any() else 0
        self.train_samples = np.arange(sig.n) <= last
        #: cached rows by key, least recently used first; ``_rows_bytes`` their size;
        #: ``_asked_again`` the keys found in the cache at least once
        self._rows: dict = {}
        self._rows_bytes = 0
        self._asked_again: set = set()
        #: full-rate effective inputs, the most recent :data:`U_CACHE` only: a search over
        #: a delay or a saturation level makes one per variant, and their rows are cached
        self._u: dict = {}
        #: one full-rate helper per name, for the most recent model's input only
        self._per_input: dict = {}

    # ---- the input -----------------------------------------------------------------
    @staticmethod
    def input_key(model: Model) -> tuple:
        return tuple((t.physics, t.theta) for t in model.input_terms())

    def u_eff(self, model: Model, extra: Term | None = None) -> np.ndarray:
        """The force that reaches the arm (n,): the recording's input through the model's
        input terms (and ``extra``): saturation first, then the delay, as in the drive,
        then a sensor's lag (:mod:`servo.diagnose.sensor_lag`: it commutes with the
        linear dynamics, so it acts on the force as on the position)."""
        terms = model.input_terms() + ([extra] if extra is not None else [])
        key = tuple(sorted((t.physics, t.theta) for t in terms))
        if not key:
            return self.sig.u
        if key in self._u:
            self._u[key] = self._u.pop(key)  # most recent last
            return self._u[key]
        u = self.sig.u
        for phys in sorted((p for p in VOCABULARY.values() if p.path.kind == "input"), key=lambda p: p.path.path_order):
            for t in terms:
                if t.physics == phys.name:
                    u = phys.path.transform(u, t.params, self.sig.dt)
        while len(self._u) >= U_CACHE:
            del self._u[next(iter(self._u))]
        self._u[key] = u
        return u

    def cached_rows(self, key, make) -> np.ndarray:
        """Rows for ``key``, computed by ``make()`` (a (m,) or (m, k) array) unless cached.
        The cache holds at most :data:`ROWS_BUDGET` bytes.  Beyond it, the entries never
        asked for again go first, the newest of them first: a round's variants come back
        in the next round in the same order, and those it kept are found there (at 1e6
        samples with the cache held to 51 MB, 226 columns built instead of 259 when the
        least recently used went first; 149 with the whole cache); then the least
        recently used."""
        rows = self._rows.pop(key, None)
        if rows is None:
            rows = make()
            self._rows_bytes += rows.nbytes
        else:
            self._asked_again.add(key)
        self._rows[key] = rows  # most recent last
        while self._rows_bytes > ROWS_BUDGET and len(self._rows) > 1:
            cold = (k for k in reversed(self._rows) if k != key and k not in self._asked_again)
            drop = next(cold, None)
            if drop is None:
                drop = next(iter(self._rows))
            self._rows_bytes -= self._rows.pop(drop).nbytes
            self._asked_again.discard(drop)
        return rows

    def forget(self, keep=()) -> None:
        """Drop the cached rows, except the targets and the terms' rows of the models in
        ``keep``: what a diagnosis asks for again once its rounds have chosen (the rows
        of the variants it scored would otherwise stay until it ends)."""
        kept = set()
        for model in keep:
            kept.add(("y",) + self.input_key(model))
            kept.update(self._term_key(VOCABULARY[t.physics], t, model) for t in model.column_terms())
        for key in [k for k in self._rows if k not in kept]:
            self._rows_bytes -= self._rows.pop(key).nbytes
            self._asked_again.discard(key)

    def target_raw(self, model: Model, extra: Term | None = None) -> np.ndarray:
        """Rows of the aligned effective force (m,).  A delay tried on top of a model
        without one (``extra``, the screening of ``time_delay``) is interpolated from the
        force filtered once (:class:`servo.diagnose.delayed.DelayedForce`, equal to the
        exact chain's rows to rounding); the exact chain serves every other case."""
        key = ("y",) + self.input_key(model) + ((extra.physics, extra.theta) if extra else ())
        if key in self._rows:
            return self.cached_rows(key, None)
        if extra is not None and not model.has(extra.physics):
            fast = VOCABULARY[extra.physics].search.screen_target(self, model, extra.params)
            if fast is not None:
                return self.cached_rows(key, lambda: fast)
        u = self.u_eff(model, extra)
        return self.cached_rows(key, lambda: self.sig.force_rows(u))

    def per_input(self, name: str, model: Model, build):
        """``build()``'s result for ``model``'s effective input, kept under ``name`` for
        the most recent input only (a full-rate array or an object holding one): what a
        term's :meth:`~servo.physics.base.Search.screen_target` derives once from
        the input and reuses over its grid."""
        key = self.input_key(model)
        held = self._per_input.get(name)
        if held is None or held[0] != key:
            held = self._per_input[name] = (key, build())
        return held[1]

    def delayed_force(self, model: Model):
        """The :class:`~servo.diagnose.delayed.DelayedForce` of ``model``'s effective input
        (what a delay's :meth:`~servo.physics.base.Search.screen_target` interpolates)."""
        from servo.diagnose.delayed import DelayedForce

        q = self.sig.settings.decimate
        return self.per_input("delayed_force", model, lambda: DelayedForce(self.sig, self.u_eff(model), 2.0 * q + 1.0))

    def column_design(self, phys, model: Model):
        """The design whose ``sig`` the term ``phys``'s columns read under ``model``: this
        one, or where ``model`` holds a sensor lag and ``phys`` is nonlinear in the motion,
        the lag-corrected one (:class:`servo.diagnose.sensor_lag.LagCorrected`: the motion
        the arm made, its rows through the lag)."""
        for name in dict.fromkeys(t.physics for t in model.terms):
            other = VOCABULARY[name].path.column_design(self, model, phys)
            if other is not None:
                return other
        return self

    def full_columns(self, term: Term, model: Model) -> np.ndarray:
        """Full-rate columns (n, k) of ``term`` under ``model`` as the force balance of the
        measured motion sees them (through a sensor lag where :meth:`column_design` says),
        zero before a gated term's onset (``from_s``), as in :meth:`term_rows`."""
        phys = VOCABULARY[term.physics]
        d = self.column_design(phys, model)
        p = {k: v for k, v in term.params.items() if k != GATE}
        F = np.atleast_2d(np.asarray(phys.full(d, p, self.u_eff(model)), dtype=float).T).T
        if GATE in term.params:
            F = F * (self.sig.t >= term.params[GATE])[:, None]
        return F if d is self else d.sig.seen(F)

    def term_rows(self, term: Term, model: Model) -> np.ndarray:
        """Rows of the columns of ``term`` (m, k) under ``model``'s input.  A term gated in
        time (an onset ``from_s``, :mod:`servo.diagnose.partial`) has its full-rate
        columns set to zero before the onset, then the rows' filter, as the force it
        models (its search gates the rows instead, an approximation within the
        decimation filter's reach of the onset)."""
        phys = VOCABULARY[term.physics]
        key = self._term_key(phys, term, model)
        d = self.column_design(phys, model)
        if GATE in term.params:
            p = term.params
            t0 = p.pop(GATE)

            def make():
                F = np.atleast_2d(phys.full(d, p, self.u_eff(model)).T).T * (self.sig.t >= t0)[:, None]
                return np.column_stack([d.sig.rows(np.ascontiguousarray(F[:, j])) for j in range(F.shape[1])])

            return self.cached_rows(key, make)
        return self.cached_rows(key, lambda: phys.rows(d, term.params, self.u_eff(model)))

    def _term_key(self, phys, term: Term, model: Model) -> tuple:
        """The cache key of :meth:`term_rows` of ``term`` (vocabulary entry ``phys``) under ``model``."""
        key = (term.physics, term.theta) + (self.input_key(model) if phys.path.uses_input or phys.path.signs_by_input else ())
        if self.column_design(phys, model) is not self:
            key += self.input_key(model)
        return key

    def variant_rows(self, physics: str, theta: dict, model: Model) -> np.ndarray:
        """:meth:`term_rows` of the vocabulary term ``physics`` at ``theta``."""
        return self.term_rows(Term.make(physics, theta), model)

    def matrix(self, model: Model, extra: Term | None = None) -> tuple[np.ndarray, np.ndarray, list]:
        """``(y, Phi, names)``: the target (force minus the fixed terms, (m,)), the free
        columns (m, p) and their ``(physics, coefficient)`` names.  ``extra`` is an input
        term tried on top of the model (the columns are not recomputed for it)."""
        y = self.target(model, extra)
        cols, names = [], []
        for t in model.column_terms():
            if t.free:
                cols.append(self.term_rows(t, model))
                names += [(t.physics, c) for c in VOCABULARY[t.physics].coefs]
        Phi = np.column_stack(cols) if cols else np.zeros((y.size, 0))
        return y, Phi, names

    def target(self, model: Model, extra: Term | None = None) -> np.ndarray:
        """The target of :meth:`matrix` alone (m,), a new array: the aligned effective
        force minus the model's fixed terms (what an input variant changes; its free
        columns are the model's)."""
        y = self.target_raw(model, extra).copy()
        for t in model.column_terms():
            if not t.free:
                y -= self.term_rows(t, model) @ np.asarray(t.coef)
        return y


__all__ = ["GATE", "Design", "Model", "Term"]
