"""The search: forward selection of effects with tests, validation and backward elimination.

:func:`run` is the whole loop.  Each step

1. asks every candidate kind for its best member given the current model
   (:class:`~accal.closure.candidates.Context`);
2. tests each proposal under the residual's coloured noise with its multiplicity
   (:func:`accal.closure.significance.test_proposal`);
3. takes the significant proposals, most significant first (the last-resort kinds,
   free-frequency sinusoids, after the others), and validates them
   (:func:`accal.closure.validation.validate`: identifiable from the signal,
   confirmed on held-out stretches, physically plausible); the first that passes is
   added, those that fail are reported with the reason and not proposed again;
4. re-tests every earlier effect given the others and drops one that is no longer
   significant (it was standing in for the new one), and rejects a bias step whose
   epoch is no longer determined given the others
   (:func:`accal.closure.validation.epoch_reason`).

It stops when nothing significant is left, after ``max_effects`` effects, or after
:data:`MAX_REJECTED` rejections.  :class:`Search` holds the state and its caches.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import special

from accal.closure.basis import Basis, FitResult
from accal.closure.candidates import EXP_LONG_FRACTION, Context, Proposal, exponential_drift
from accal.closure.final import with_jacobian
from accal.closure.kinds import EFFECT_NAMES, kind_of
from accal.closure.residual import Grid
from accal.closure.significance import Tested, p_given_others, test_proposal
from accal.closure.softstep import with_wide_ramp
from accal.closure.validation import SignalProxies, Verdict, epoch_reason, validate

__all__ = ["MAX_REJECTED", "Found", "Search", "augmented", "run"]

#: Most significant candidates rejected (reported, not added) in one search.
MAX_REJECTED = 6


@dataclass(eq=False)
class Found:
    """An effect in the model (or a rejected candidate): the proposal and its checks.

    ``aug`` is the proposal as it enters the model: with the Jacobian columns of its
    searched time constant or lag (:func:`accal.closure.final.with_jacobian`), so that
    later candidates are tested with that parameter free, not held (a settling shape
    held at its searched τ left a misfit that a second shape then "explained").
    """

    prop: Proposal
    p_adj: float
    verdict: Verdict
    stat: float = float("nan")
    aug: Proposal | None = None
    #: Admitted as a step of a pair of steps tested as a whole: alone, it must be
    #: tested again (:meth:`Search.eliminate`).
    member: bool = False

    @property
    def model_prop(self) -> Proposal:
        """The proposal as it enters the model (Jacobian columns included)."""
        return self.aug if self.aug is not None else self.prop


@dataclass
class Search:
    """State of one search (see the module notes)."""

    grid: Grid
    t_all: NDArray[np.float64]
    use: NDArray[np.bool_]
    t0: float
    span: float
    y_u: NDArray[np.float64]
    basis0: Basis
    bias0: Basis | None
    signal0: Basis | None
    builders: list[tuple[str, Callable[[Context], list[Proposal]]]]
    n_families: int
    alpha: float
    options: dict[str, Any]
    aux: dict[str, NDArray[np.float64]]
    orbit_period: float | None
    base_labels: frozenset[str]
    chan_all: NDArray[np.int64] | None = None
    names: tuple[str, ...] = ()
    reference: NDArray[np.float64] | None = None
    beta: NDArray[np.float64] | None = None
    proxies: SignalProxies | None = None
    found: list[Found] = field(default_factory=list)
    rejected: list[Found] = field(default_factory=list)
    removed: list[Found] = field(default_factory=list)
    notes: dict[tuple, dict[str, Any]] = field(default_factory=dict)
    iterations: int = 0
    #: The selection stopped before it had finished (``run``'s ``until``).
    paused: bool = False
    cache: dict = field(default_factory=dict, repr=False)
    _states: dict = field(default_factory=dict, repr=False)

    # ---------------------------------------------------------------- model states
    def drop_caches(self) -> None:
        """Forget the cached model states and candidate caches (rebuilt when needed)."""
        self.cache.clear()
        self._states.clear()

    def state(self, found: Sequence[Found]) -> tuple[Basis, FitResult, NDArray[np.float64]]:
        """Basis, fit and leverage spectrum of the null model plus ``found`` (cached).

        Keyed by the effects themselves (:class:`Found` compares by identity), so the
        cache keeps them alive: a key of ``id()`` values was hit by new effects at the
        addresses of freed ones (the final fit's copies), which then got a model that
        already held them (p = 1, a 30σ effect dropped on about one run in eight).
        """
        key = tuple(found)
        if key not in self._states:
            basis = self.basis0
            if found:
                basis = basis.extend(
                    np.column_stack([f.model_prop.columns[self.use] for f in found])
                )
            if len(self._states) >= 16:
                self._states.pop(next(iter(self._states)))
            self._states[key] = (basis, basis.fit(self.y_u), self.leverage(basis))
        return self._states[key]

    def leverage(self, basis: Basis) -> NDArray[np.float64]:
        """Leverage spectrum, with the measured suppression of the null model (``beta``)."""
        lev = basis.leverage(self.grid)
        if self.beta is None:
            return lev
        nc = np.maximum(self.grid.counts, 1.0)[:, None]
        return nc - (nc - lev) * self.beta

    def bias_state(self, found: Sequence[Found]) -> Basis | None:
        """The bias part of the null model plus ``found`` (None: no signal part)."""
        if self.bias0 is None:
            return None
        if not found:
            return self.bias0
        return self.bias0.extend(np.column_stack([f.model_prop.columns[self.use] for f in found]))

    def signal_state(self, found: Sequence[Found], basis: Basis) -> Basis:
        """The model with the signal's extension (``signal0``) plus ``found``, else ``basis``."""
        if self.signal0 is None:
            return basis
        if not found:
            return self.signal0
        return self.signal0.extend(np.column_stack([f.model_prop.columns[self.use] for f in found]))

    def context(self, found: Sequence[Found], basis, fit, lev) -> Context:
        """What the builders see."""
        blocked = {(f.prop.name, f.prop.channel) for f in self.rejected if _keyed(f.prop) is None}
        blocked |= {(f.prop.name, f.prop.channel, _keyed(f.prop)) for f in self.rejected}
        freqs = [g for f in found for g in _freqs(f.prop)]
        orbit = [f for f in found if f.prop.name == "periodic" and f.prop.channel == "orbit"]
        return Context(
            t_all=self.t_all,
            use=self.use,
            t0=self.t0,
            span=self.span,
            grid=self.grid,
            residual=fit.resid,
            basis=basis,
            leverage=lev,
            labels=self.base_labels | {lb for f in found for lb in f.prop.labels},
            aux=self.aux,
            orbit_period=self.orbit_period,
            options=self.options,
            channel_all=self.chan_all,
            channel_names=self.names,
            orbit_frequency=float(orbit[0].prop.params["frequency"]) if orbit else None,
            n_lines=sum(f.prop.name == "periodic" and f.prop.channel == "line" for f in found),
            model_freqs=tuple(freqs),
            cache=self.cache,
            reference=self.reference,
            blocked=frozenset(blocked),
            proxies=None if self.proxies is None else self.proxies.columns[self.use],
            coupled={
                str(f.prop.channel): f.prop.path
                for f in found
                if f.prop.name == "auxiliary" and not f.prop.squared
            },
        )

    # ---------------------------------------------------------------- one step's parts
    def propose_by_builder(
        self, ctx: Context, kept: dict[str, list[Proposal]] | None = None
    ) -> dict[str, list[Proposal]]:
        """Each builder's proposals; notes (untestable candidates) are recorded.  A
        builder in ``kept`` is not run again, its proposals are those given
        (:func:`_kept_builders`)."""
        out: dict[str, list[Proposal]] = {}
        for name, build in self.builders:
            if kept is not None and name in kept:
                out[name] = kept[name]
                continue
            out[name] = []
            for prop in build(ctx):
                if prop.note is not None:
                    self.note(prop.name, prop.channel, prop.note, prop.params)
                else:
                    out[name].append(prop)
        return out

    def test(self, basis, fit, lev, prop: Proposal) -> Tested | None:
        """Test of ``prop`` on top of the model ``basis``."""
        return test_proposal(self.grid, basis, fit.resid, lev, prop, self.use, self.n_families)

    def p_without(self, i: int, found: Sequence[Found] | None = None) -> float:
        """Corrected p of effect ``i`` of ``found`` given the others."""
        found = self.found if found is None else found
        others = [g for j, g in enumerate(found) if j != i]
        basis, _, lev = self.state(others)
        return p_given_others(
            self.grid, basis, lev, self.y_u, found[i].prop, self.use, self.n_families
        )

    def p_final(self, i: int, found: Sequence[Found]) -> float:
        """Corrected p of effect ``i`` of ``found`` (augmented: :func:`_final_effects`
        of :mod:`accal.closure.select`) given the others; for a bias step with the
        local columns of its ramp (:mod:`accal.closure.transition`), of the step
        alone with those columns in the model.

        The ramp's columns are the step's shape, not evidence of a step: tested with it,
        they took a thruster firing's remnant at the epoch (a clean day of the QA
        helper's generator, AR(1) noise and firings: a step of −5.2e-10 ± 5.4e-10 m/s²,
        p 0 with its ramp, its epoch anywhere in the day, was removed).
        """
        f = found[i]
        k = int(f.prop.params.get("jacobian") or 0)
        ramp = f.prop.name == "bias_step" and f.prop.params.get("transition")
        if not ramp or not 0 < k < f.prop.columns.shape[1]:
            return self.p_without(i, found)
        others = [g for j, g in enumerate(found) if j != i]
        basis, _, _ = self.state(others)
        basis = basis.extend(f.prop.columns[self.use][:, k:])
        main = dataclasses.replace(f.prop, columns=f.prop.columns[:, :k], labels=f.prop.labels[:k])
        return p_given_others(
            self.grid, basis, self.leverage(basis), self.y_u, main, self.use, self.n_families
        )

    def validate_args(self, tested: Tested) -> dict[str, Any]:
        """:func:`~accal.closure.validation.validate`'s test arguments for ``tested``
        (the other axes, the admitting test, its multiplicity, alpha)."""
        factor = max(tested.prop.multiplicity, 1.0) * max(self.n_families, 1)
        return {"proxies": self.proxies, "wald": tested.wald, "factor": factor, "alpha": self.alpha}

    def note(self, name: str, channel: str | None, text: str, params=None) -> None:
        """Record a note once."""
        key = (name, channel, text)
        if key not in self.notes:
            d: dict[str, Any] = {"name": name, "channel": channel, "note": text}
            if params:
                d["details"] = {k: v for k, v in dict(params).items() if _jsonable(v)}
            self.notes[key] = d

    def eliminate(self, n_new: int = 1) -> None:
        """Drop the least significant earlier effect while one is no longer significant,
        then a step whose epoch is no longer determined (:meth:`_drop_undetermined_step`),
        until neither is left.

        ``n_new``: effects just added (a pair of steps is two, each re-tested too).
        A step of a pair of steps left alone (the other one dropped) is tested again
        on its own, given nothing: it was admitted only with the other (QA helper's
        generator, white noise: such lone steps of ~3e-11 m/s², corrected p 1 alone,
        were removed from the calibrated series on 3 of 72 clean axes).
        """
        while True:
            while len(self.found) > 1:
                last = len(self.found) - (1 if n_new <= 1 else 0)
                ps = [self.p_without(i) for i in range(last)]
                worst = int(np.argmax(ps))
                if ps[worst] < self.alpha:
                    break
                self.removed.append(self.found.pop(worst))
            if len(self.found) == 1 and self.found[0].member and self.p_without(0) >= self.alpha:
                self.removed.append(self.found.pop())
            if not self._drop_undetermined_step():
                return

    def _drop_undetermined_step(self) -> bool:
        """Move the first step whose epoch is no longer determined given the other
        effects (:func:`~accal.closure.validation.epoch_reason`) to the rejected ones;
        whether one was."""
        for i, f in enumerate(self.found):
            if f.prop.name != "bias_step" or f.prop.params.get("pair"):
                continue
            others = [g for j, g in enumerate(self.found) if j != i]
            basis, fit, lev = self.state(others)
            tested = self.test(basis, fit, lev, f.prop)
            if tested is None:
                continue
            why = epoch_reason(f.prop, self.context(others, basis, fit, lev), tested.wald)
            if why:
                self.found.pop(i)
                verdict = dataclasses.replace(f.verdict, ok=False, reason=why)
                self.rejected.append(dataclasses.replace(f, verdict=verdict))
                return True
        return False


def augmented(prop: Proposal, s: Search, basis: Basis) -> Proposal:
    """``prop`` as it enters the model given ``basis``: with its Jacobian or transition
    columns (:func:`accal.closure.final.with_jacobian`), a bias step over minutes as a
    ramp (:func:`accal.closure.softstep.with_wide_ramp`)."""
    return with_wide_ramp(with_jacobian(prop, s.t_all, s.t0, s.use, basis), s, basis)


def run(
    s: Search,
    max_effects: int,
    stop: Callable[[Search], bool] | None = None,
    until: Callable[[Search], bool] | None = None,
) -> Search:
    """Forward selection with validation and backward elimination (module notes).

    ``until``: pause the selection after a step whose model it holds true
    (``s.paused``; calling ``run`` again goes on from there).
    """
    s.paused = False
    seen: set[tuple] = set()
    kept: tuple[dict, dict] | None = None  # proposals and tests kept on the same model
    while len(s.found) < max_effects and s.iterations < 3 * max_effects:
        if stop is not None and stop(s):
            break
        basis, fit, lev = s.state(s.found)
        ctx = s.context(s.found, basis, fit, lev)
        s.iterations += 1
        by_builder = s.propose_by_builder(ctx, None if kept is None else kept[0])
        done = {} if kept is None else kept[1]
        tested = [
            t
            for t in (
                done[id(p)] if id(p) in done else s.test(basis, fit, lev, p)
                for props in by_builder.values()
                for p in props
            )
            if t
        ]
        n_rejected = len(s.rejected)
        # the kinds that name a cause before the last-resort ones (Kind.last_resort),
        # then most significant first (the log p-value, exact far below float's range: of
        # two candidates explaining the same structure the one with fewer columns wins),
        # then the most power
        significant = sorted(
            (t for t in tested if t.p_adj < s.alpha),
            key=lambda t: (kind_of(t.prop.name).last_resort, t.log_p, -t.power),
        )
        # a pair (a channel with its square) only when its single coupling is not
        # significant, or when the single was rejected (a linear coupling that lines at
        # the channel's periods explain may still be the proxy of a quadratic one)
        singles = {t.prop.name for t in significant if not t.prop.params.get("pair")}
        significant = sorted(
            significant, key=lambda t: bool(t.prop.params.get("pair")) and t.prop.name in singles
        )
        added = False
        for t in significant:
            verdict = validate(
                t.prop,
                ctx,
                s.bias_state(s.found),
                s.t_all[s.use],
                s.signal_state(s.found, basis),
                **s.validate_args(t),
            )
            entry = Found(t.prop, t.p_adj, verdict, t.wald.stat)
            if verdict.ok:
                parts = _parts(t.prop)
                for part in parts:
                    # a step of a pair of steps; not a coupling of a pair with its
                    # square, which stays when the square goes (the selection took the
                    # pair because the coupling alone was not significant or rejected:
                    # test_lag_and_low_pass_on_half_a_day_with_gaps_keep_the_coupling)
                    member = len(parts) > 1 and part.name == "bias_step"
                    f = Found(part, t.p_adj, verdict, t.wald.stat, member=member)
                    f.aug = augmented(part, s, basis)
                    s.found.append(f)
                added = True
                break
            s.rejected.append(entry)
            if len(s.rejected) >= MAX_REJECTED:
                break
        if not added:
            if significant and len(s.rejected) < MAX_REJECTED:
                # every significant one was rejected: propose again without them, on
                # the same model (the builders that proposed none of them not re-run)
                kept = _kept_builders(by_builder, tested, s.rejected[n_rejected:])
                continue
            break
        kept = None
        s.eliminate(len(_parts(t.prop)))
        key = tuple(sorted(_model_key(f.prop) for f in s.found))
        if key in seen:
            break
        seen.add(key)
        if until is not None and until(s):
            s.paused = True
            break
    return s


def _kept_builders(
    by_builder: dict[str, list[Proposal]], tested: list[Tested], rejected: list[Found]
) -> tuple[dict[str, list[Proposal]], dict[int, Tested]]:
    """What a selection step proposing again on the same model keeps: the proposals of
    the builders none of whose proposals was just rejected, with their tests.

    Such a step only has more rejected candidates than the last one; a builder
    depends on the model, its own kind's rejections (``Context.blocked``) and its
    caches, so one with no proposal rejected proposes the same again.  Kept only for
    the registered kinds, and not for ``periodic``, whose builder leaves each line it
    finds modulated like the signal out of its next call (``modulated_freqs``).  A
    platform run with a rejected pair (channel and square): the exponential, step
    and in-period shape builders and their tests, ~0.4 s, not run twice.
    """
    gone = {id(f.prop) for f in rejected}
    keep = {
        name: props
        for name, props in by_builder.items()
        if name in EFFECT_NAMES and name != "periodic" and not any(id(p) in gone for p in props)
    }
    ids = {id(p) for props in keep.values() for p in props}
    return keep, {id(t.prop): t for t in tested if id(t.prop) in ids}


#: How much larger (Wald statistic less a χ²₁ 99 % quantile per parameter) a slow
#: exponential's score must be to replace the polynomial drift terms found: an e^50
#: likelihood ratio (calibrated in the earlier engine: quadratic-only days scored 1-43
#: for the exponential, slow decays 117-27,000).
SWAP_MIN_GAIN = 100.0


def swap_smooth(s: Search) -> None:
    """Replace polynomial drift terms by one slow exponential settling when it scores far more.

    The forward search caps an exponential's time constant at a quarter of the span
    (a slower one took a true cubic's place); a slower decay is then taken by a
    quadratic and a cubic, and the bias keeps its amplitude (z ~ 100-400 on
    simulated decays of T = 30,000-60,000 s).  Here the exponential is searched up
    to the whole span, given the other effects, and replaces the polynomial terms
    when its score beats theirs by :data:`SWAP_MIN_GAIN`.
    """
    enabled = s.options.get("enabled", ())
    polys = [i for i, f in enumerate(s.found) if f.prop.name in ("quadratic_drift", "cubic_drift")]
    if not polys or "exponential_drift" not in enabled:
        return
    if any(f.prop.name == "exponential_drift" for f in s.found):
        return
    rest = [f for i, f in enumerate(s.found) if i not in polys]
    basis, fit, lev = s.state(rest)
    ctx = s.context(rest, basis, fit, lev)
    opts = {**s.options, "exp_tau_max": EXP_LONG_FRACTION * s.span}
    props = exponential_drift(dataclasses.replace(ctx, options=opts))
    if not props:
        return
    t_exp = s.test(basis, fit, lev, props[0])
    cols = np.column_stack([s.found[i].prop.columns for i in polys])
    poly = Proposal("quadratic_drift", None, cols, (), 1.0, {})
    t_poly = s.test(basis, fit, lev, poly)
    if t_exp is None or t_poly is None:
        return
    pen = float(special.chdtri(1, 0.01))  # χ²(1) 99 % quantile

    def score(t: Tested, k: int) -> float:
        return float(t.wald.stat * t.wald.q) - pen * k

    if score(t_exp, 2) <= score(t_poly, cols.shape[1]) + SWAP_MIN_GAIN:
        return
    verdict = validate(
        t_exp.prop,
        ctx,
        s.bias_state(rest),
        s.t_all[s.use],
        s.signal_state(rest, basis),
        **s.validate_args(t_exp),
    )
    if not verdict.ok:
        return
    new = Found(t_exp.prop, t_exp.p_adj, verdict, t_exp.wald.stat)
    new.aug = with_jacobian(t_exp.prop, s.t_all, s.t0, s.use, basis)
    s.removed += [s.found[i] for i in polys]
    s.found = [*rest, new]


def _parts(prop: Proposal) -> list[Proposal]:
    """A proposal tested as a whole (a pair of steps) as the effects it holds."""
    parts = prop.params.get("parts")
    if not parts:
        return [prop]
    out = []
    for idx, params in parts:
        params = dict(params)
        out.append(
            Proposal(
                prop.name,
                params.pop("channel", prop.channel),
                prop.columns[:, idx],
                tuple(prop.labels[i] for i in idx),
                prop.multiplicity,
                params,
                None if prop.axes is None else tuple(prop.axes[i] for i in idx),
            )
        )
    return out


def _keyed(prop: Proposal):
    """What identifies a rejected member beyond its kind and channel (a line's frequency)."""
    if prop.name == "periodic" and prop.channel == "line":
        return float(prop.params["frequency"])
    if prop.name == "bias_step":
        return float(prop.params["epoch"])
    return None


def _model_key(prop: Proposal) -> tuple:
    return (
        prop.name,
        str(prop.channel),
        tuple(sorted((k, repr(v)) for k, v in prop.params.items())),
    )


def _freqs(prop: Proposal) -> list[float]:
    if prop.name != "periodic" or prop.params.get("frequency") is None:
        return []
    f = float(prop.params["frequency"])
    return [n * f for n in prop.params.get("harmonics", (1,))]


def _jsonable(v: Any) -> bool:
    return isinstance(v, str | int | float | bool | type(None) | tuple | list)
