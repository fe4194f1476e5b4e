"""The paper's accumulation scheme (section 2.1), independent of the entity type.

An entity type supplies a distance with thresholds (``correspondences``, and
row by row ``pair_cost``), a rigid transform (``transform``), a merge
(``merge``) and, beyond the paper, a test of which model entities the current
frame should have observed (``expected``) and, optionally, of which the frame's images show where
the motion put them (``image_confirmed``, step 4). The core keeps, per model entity, a
confidence in log-odds, the frames that confirmed it, the frames that expected
or confirmed it since it was created (``views``), when it was last confirmed,
and its first observation (``essentials`` of it, in the sensor's and in the
model's frame).

Update rule per frame, for observed entities brought into the model's frame
by the known motion (the entity type's ``transform``):

1. Correspondences between model and observation by the entity's metric.
2. Static entities are contradicted (beyond the paper): where this frame's
   observations are explained better, by ``static_margin`` of cost, by an
   entity's first observation held still in the sensor's frame than by the
   entity where the model has it, the entity does not move with the object: it
   is background, ``L += contradiction``, and its pairs neither confirm nor
   merge. Background
   is extracted as reliably as the object, but at the place a static thing
   has, so this catches it in the first frame after its first one where the
   object moved there by more than the gate; where the object did not move
   at an entity since its first observation, the frame cannot tell and says
   nothing. Where lines are everywhere (a tiled floor, wood grain), the
   entity's model place often shows another line too, and no single frame
   tells the two places apart by the margin; the frames together may: each
   adds the difference of the two costs (model place less still place,
   clipped to [-1, 1]; 1 where only the still place shows something, -1
   where only the model place does) to a sum kept since the entity's first
   observation, and once the sum exceeds ``static_evidence`` the entity is
   contradicted in every frame that judges it (the sum is never reset: only
   frames that show it at its model place and not at its still place take it
   back down). ``make suite`` (4 runs a row,
   2026-12-07) against the single-frame test alone: every simulated and
   devset row the same to the digit; on the real teabox the share of the
   accepted length that ``accum check`` finds staying still in view 0.083 ->
   0.070 (lower in each of the 4 runs), surface precision 0.555 -> 0.558,
   completeness 0.666 -> 0.663. A threshold of 0.25 gave 0.068, and no
   negative term (evidence only where the still place shows something) 0.072.
   Measured and not kept: a frame whose still place explains an entity's
   observation at least as well as its model place not confirming it (every
   row the same but sim_102's precision, 0.971 -> 0.975, and the teabox's
   still share, 0.071).
3. Every other model entity with a corresponding observation is confirmed:
   ``L += log(p_detect / (p_false w^widening))``, w >= 1 being how much wider
   than the paper's the tightest gate that paired it was (the metric gates by
   the pair's own uncertainty): false things fall into a wider gate
   likelier. Merging is one-to-one (mutually best pairs, in rounds, by
   ascending cost): each observation is averaged into one model entity.
   Confirming is not: local entities are cut anew in every frame (an edge may
   be four pieces in the model and three in a frame), and a piece whose
   stretch was observed must not be punished for the cut.
4. Model entities the frame should have observed (``expected``) but did not
   are weakened by what a miss tells of *this* entity:
   ``L += log((1 - r) / (1 - p_false))`` with r its own detection rate, the
   mean of the Beta posterior of its confirmations over its views,
   ``r = (hits + prior_rate prior_views) / (views + prior_views)``, clipped to
   [p_false, p_max]. Why: detection is uneven (short, crowded, low-contrast
   pieces are found in a tenth of the frames that show them, a long contrasted
   edge in nearly all), and a fixed rate of 0.5 pruned the former before they
   could be found again. A miss of an entity found rarely is nearly as likely
   if it is real as if it is not, and costs nearly nothing; one found every
   time costs up to ``log(0.3 / 0.9)``. The prior mean is the median rate
   measured on independent recordings (0.1, issue 9), so a new entity's misses
   cost nothing until it is found again; it then lives on the tentative
   bound (step 7) and the contradiction (step 2). Entities that could not have
   been observed keep their confidence: an edge that turned out of view, or
   behind the object, is not punished. Measured and not kept (``make suite``'s
   accumulation, 4 runs a row, 2026-12-07): ``p_max`` 0.3 (a miss costs at most
   log(0.7 / 0.9)): the real teabox's 80 frames, where a fifth of the box's edge
   length that single frames got right twice or more is in no model segment,
   completeness 0.658 -> 0.711 (found in any confidence 0.706 -> 0.752), the
   completeness mean 0.748 -> 0.755 and worst row 0.455 -> 0.467, but the
   precision median 0.969 -> 0.964 (sim_104 0.980 -> 0.965, sim_110 0.976 ->
   0.958, sim_103 under 0.95); ``p_max`` 0.5: the teabox 0.677, completeness
   mean 0.750, precision median 0.968, within the runs' scatter; on the teabox
   alone, ``tentative_frames`` 30 gave 0.671 and a wider gate (5 mm, 10
   degrees) 0.643.
   Beyond the paper, off by default (``image_confirmation``, ``accum accumulate --image-confirm``):
   an entity that no observation confirmed but whose place the frame's images show (the entity
   type's ``image_confirmed``: for line segments, the edge in both images where the motion moved it,
   from a new aspect, where the object moved across it since its first observation, so it needs the
   first observations that step 2 keeps, i.e. ``static_margin``) gains ``image_confirmation``
   (``IMAGE_CONFIRMATION``, 0.6 against a confirmation's 1.61: a new entity that no observation
   confirms needs two such frames) instead of a miss, and counts as confirmed for the
   ``tentative_frames`` bound (an entity the images keep showing is not stale; for line segments
   that frame also gives it no planes of unmatched left pieces, which ``pipeline`` looks for only where
   no frame confirmed an entity). Why: the frames' 3D
   segments, not the accumulation, limit completeness (``make suite``: the model covers about what
   single frames got right twice), and a short edge's later pieces are often tilted in depth past the
   metric's gate, though the images show the edge where the segment projects. The images judge a
   segment's 3D place only from another aspect (from the first one they repeat its plane whatever its
   tilt) and only where its still place projects elsewhere. Never with poses refined on the same
   images (``--motion tracked``): those put the model on the images' edges. Measured
   (``benchmarks/suite.py --image-confirm``, 4 runs a row, 2026-12-08; the README has the rows):
   completeness higher on 16 of 19 rows, precision a little lower; with poses a degree off, as the
   real teabox's, it finds nothing. Off by default because tracking with its fuller models was less
   safe: the tracking scoreboard's sim_201 tracked a frame 10.3 mm off (``benchmarks/track_suite.py
   --image-confirm``). Measured with its first form (README) on dev_cube_small and sim_104
   (completeness / precision): a tolerance
   of 0.6 px instead of 0.4 (``LineModelParams.image_tolerance_px``) 0.474 / 0.896 and 0.840 / 0.966
   against 0.470 / 0.919 and 0.838 / 0.974; with that tolerance, 1.2 instead of 0.6 accepted entities
   seen once and shown once (dev_cube_small 0.495 / 0.826), and with it, without the new-aspect test
   sim_104 0.842 / 0.911, storing the aspects the images confirmed as views 0.841 / 0.923 (the views
   also decide which directions count as pinned).
5. Model entities that duplicate each other (the entity type's ``same``) are
   merged: they would otherwise compete for the same observations.
6. Unmatched observations join the model with confidence ``initial``.
7. Entities below ``floor`` are pruned, and so are tentative ones
   (confidence < 0.5) not confirmed for ``tentative_frames`` frames, which
   bounds the model's size on long recordings.

The log-odds L of confidence c is ``log(c / (1 - c))``, clamped to
``ceiling``. With the defaults a confirmation in the paper's gate adds log 5 =
1.61: a new entity (0.25) is accepted (>= 0.5) at its first confirmation, i.e.
seen in two frames, however many expected frames missed it in between (up to
``tentative_frames``); in a gate twice as wide it adds log 2.5 = 0.92 and the
entity needs a third frame. An entity found in one of every ten frames that
should show it then loses 1.15 over the nine misses (its rate falls from 0.4
to 0.11) and gains 1.61: it grows. One found every time (rate 0.7) and then no
more loses 1.1 per miss. A static background entity is contradicted in the
next frame that sees it again where the object moved: 0.25 -> 0.04, pruned.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from .geometry import check_transform
from .grouping import best_per_key

E = TypeVar("E")


class EntityType(Protocol[E]):
    """What the core needs of an entity type. Entities are a struct of arrays (first axis N)."""

    def size(self, entities: E) -> int: ...

    def select(self, entities: E, index: np.ndarray) -> E: ...

    def concatenate(self, first: E, second: E) -> E: ...

    def transform(self, entities: E, T_new_old: np.ndarray) -> E: ...

    def correspondences(self, model: E, observed: E) -> tuple[np.ndarray, ...]:
        """(model index, observed index, cost) of all pairs within the metric's thresholds, and
        optionally (K,) each pair's widening >= 1: how many times likelier than in the nominal gate
        something false falls into the pair's (1 if not given)."""

    def merge(self, model: E, observed: E, model_index: np.ndarray, observed_index: np.ndarray,
              context: Any) -> E:
        """The model with entities ``model_index`` merged with their observations."""

    def observe(self, observed: E, context: Any) -> E:
        """Observed entities made ready to join the model (e.g. per-entity state initialised)."""

    def expected(self, model: E, context: Any, confirmed: np.ndarray | None = None) -> np.ndarray:
        """(N,) bool: the frame described by ``context`` should have observed these entities.
        ``confirmed`` (N,) bool: those the frame did observe, whose answer does not matter (a type may
        skip its costlier tests for them)."""

    def pair_cost(self, a: E, b: E) -> np.ndarray:
        """(N,) the metric's cost of the pairs (a[k], b[k]), row by row; inf where they do not correspond."""

    def essentials(self, entities: E) -> E:
        """What ``correspondences`` needs of entities, to keep as their first observation."""

    def same(self, model: E, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mask, cost) for pairs of model entities: which describe the same thing (a test
        stricter than ``correspondences``, which must tolerate an observation's noise)."""


IMAGE_CONFIRMATION = 0.6   # ``UpdateRule.image_confirmation`` of ``accum accumulate --image-confirm`` (step 4)


def image_confirming(on: bool) -> "UpdateRule":
    """The default rule, with ``IMAGE_CONFIRMATION`` where ``on`` (``accum accumulate --image-confirm``)."""
    return UpdateRule(image_confirmation=IMAGE_CONFIRMATION if on else None)


def logit(p: float) -> float:
    return float(np.log(p / (1.0 - p)))


@dataclass(frozen=True)
class UpdateRule:
    p_detect: float = 0.5      # a confirmation's likelihood: it adds log(p_detect / p_false)
    prior_rate: float = 0.1    # prior mean of an entity's own detection rate (Beta prior) ...
    prior_views: float = 2.0   # ... and its weight, in expected views
    p_max: float = 0.7         # the largest rate believed: a miss never costs more than log(0.3 / 0.9)
    p_false: float = 0.1       # something is extracted there although the entity is not real
    contradiction: float = -2.0  # log-odds of a re-observation where a static entity would be ...
    static_margin: float | None = 0.25  # ... explaining the frame better by this cost (None: no test)
    static_evidence: float | None = 0.5  # ... or the frames since its first did by this much in sum (None: no sum)
    widening: float = 1.0      # a confirmation in a gate w times wider counts as if p_false were w^this
    initial: float = 0.25      # confidence of a new entity
    floor: float = 0.1         # pruned below
    ceiling: float = 0.995
    tentative_frames: int = 12  # a tentative entity unconfirmed this long is pruned
    image_confirmation: float | None = None  # log-odds of an unconfirmed entity the images show (step 4; None: off)

    @property
    def hit(self) -> float:
        return float(np.log(self.p_detect / self.p_false))

    def confirmation(self, widening) -> np.ndarray:
        """Log-odds of a confirmation within a gate ``widening`` times the nominal one: false
        observations fall into it that much likelier (``p_false`` times ``widening``), never
        making a confirmation count against the entity."""
        return np.log(self.p_detect / np.minimum(self.p_false * np.asarray(widening) ** self.widening, self.p_detect))

    def rate(self, hits: np.ndarray, views: np.ndarray) -> np.ndarray:
        """(N,) the detection rate expected at an entity's next expected view: the Beta posterior mean
        of its ``hits`` confirmations over ``views`` expected views, clipped to [p_false, p_max]."""
        a = self.prior_rate * self.prior_views
        return np.clip((hits + a) / (views + self.prior_views), self.p_false, self.p_max)

    def miss(self, rate) -> np.ndarray:
        """Log-odds of a miss of an entity whose detection rate is ``rate``."""
        return np.log((1 - rate) / (1 - self.p_false))


@dataclass
class StepStats:
    """What one update did (counts)."""

    observed: int
    confirmed: int
    missed: int
    new: int
    pruned: int
    merged: int
    size: int
    accepted: int
    contradicted: int = 0
    image_confirmed: int = 0


def one_to_one(a: np.ndarray, b: np.ndarray, cost: np.ndarray, rounds: int = 4) -> np.ndarray:
    """Indices of pairs (a[k], b[k]) forming a one-to-one matching, by ascending cost.

    Each round keeps the pairs that are the cheapest for both their a and their
    b, then drops every pair touching a kept a or b; a few rounds recover
    nearly all of the greedy matching without a Python loop over pairs.
    """
    return _mutual_rounds(a, b + (int(a.max(initial=-1)) + 1), cost, np.arange(len(a)), rounds)   # b's apart


def disjoint_pairs(a: np.ndarray, b: np.ndarray, cost: np.ndarray, rounds: int = 4) -> np.ndarray:
    """Indices of pairs (a[k], b[k]) of one set of entities of which no two share an entity, on either
    side, by ascending cost: ``one_to_one`` with a and b one index space. (x, y) and (y, x) are one
    pair (the first of them is kept): as two, at equal cost, each was the other's rival and neither
    was ever chosen."""
    _, first = np.unique(np.column_stack([np.minimum(a, b), np.maximum(a, b)]), axis=0, return_index=True)
    return _mutual_rounds(a, b, cost, np.sort(first), rounds)


def _mutual_rounds(a: np.ndarray, b: np.ndarray, cost: np.ndarray, alive: np.ndarray, rounds: int) -> np.ndarray:
    """Indices of pairs (a[k], b[k]) among ``alive``, a and b indices of one space, of which no two share
    an index: in each round the pairs cheapest for both their ends, then every pair touching those is
    dropped (``one_to_one``, ``disjoint_pairs``)."""
    chosen = []
    used = np.zeros(int(max(a.max(initial=-1), b.max(initial=-1))) + 1, bool)
    for _ in range(rounds):
        if len(alive) == 0:
            break
        ends, costs = np.concatenate([a[alive], b[alive]]), np.concatenate([cost[alive], cost[alive]])
        cheapest = np.zeros(len(ends), bool)
        cheapest[best_per_key(ends, costs)] = True
        mutual = cheapest[:len(alive)] & cheapest[len(alive):]
        chosen.append(alive[mutual])
        used[a[alive[mutual]]] = used[b[alive[mutual]]] = True
        alive = alive[~(used[a[alive]] | used[b[alive]])]
    return np.concatenate(chosen) if chosen else np.zeros(0, np.int64)


def _sharing(model_index: np.ndarray, observed_index: np.ndarray, reach: int = 4):
    """Pairs (i, j), i != j, of model entities that correspond to the same observation."""
    order = np.argsort(observed_index, kind="stable")
    m, o = model_index[order], observed_index[order]
    pairs = [(m[:-d][o[d:] == o[:-d]], m[d:][o[d:] == o[:-d]]) for d in range(1, reach) if len(m) > d]
    if not pairs:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i, j = (np.concatenate(x) for x in zip(*pairs))
    distinct = i != j
    return i[distinct], j[distinct]


class Accumulator(Generic[E]):
    """A model of entities with confidences, updated frame by frame."""

    def __init__(self, entity_type: EntityType[E], empty: E, rule: UpdateRule = UpdateRule()):
        self.entity_type = entity_type
        self.rule = rule
        self.entities = empty
        self.log_odds = np.zeros(0)
        self.observations = np.zeros(0, np.int64)    # frames that confirmed it, its first included
        self.views = np.zeros(0, np.int64)           # frames after its first that expected or confirmed it
        self.last_confirmed = np.zeros(0, np.int64)
        self.static_sum = np.zeros(0)                # how much better staying still explained it, summed
        self.frame = 0
        # per entity, the observation it was created from, in its sensor's frame and in the model's
        self.origin_sensed: E | None = None
        self.origin: E | None = None

    @property
    def confidence(self) -> np.ndarray:
        return 1.0 / (1.0 + np.exp(-self.log_odds))

    def __len__(self) -> int:
        return len(self.log_odds)

    def update(self, observed: E, T_model_observed: np.ndarray, context: Any = None) -> StepStats:
        """Accumulate one frame's ``observed`` entities, given in their sensor's frame;
        ``T_model_observed`` (4, 4), the known motion, maps them into the model's frame
        (``InputError`` if it is not a rigid transform)."""
        T_model_observed = check_transform(T_model_observed, "T_model_observed")
        rule, kind = self.rule, self.entity_type
        sensed = observed
        observed = kind.observe(kind.transform(observed, T_model_observed), context)
        n_model, n_obs = len(self), kind.size(observed)
        all_mi, all_oi, cost, *widening = kind.correspondences(self.entities, observed)
        held = np.full(n_model, np.inf)
        np.minimum.at(held, all_mi, cost)
        contradicted = self._static(observed, T_model_observed, held)
        explained = ~contradicted[all_mi]   # pairs of a contradicted entity neither confirm nor merge
        all_mi, all_oi, cost = all_mi[explained], all_oi[explained], cost[explained]
        widening = [w[explained] for w in widening]
        keep = one_to_one(all_mi, all_oi, cost)
        mi, oi = all_mi[keep], all_oi[keep]
        confirmed = np.zeros(n_model, bool)
        confirmed[all_mi] = True
        expected = kind.expected(self.entities, context, confirmed) if n_model else np.zeros(0, bool)
        verified = self._image_confirmed(T_model_observed, context, ~confirmed & ~contradicted)
        missed = expected & ~confirmed & ~contradicted & ~verified
        candidates = _sharing(all_mi, all_oi)
        if len(mi):
            self.entities = kind.merge(self.entities, observed, mi, oi, context)
        rate = rule.rate(self.observations - 1, self.views)
        hit = np.full(n_model, rule.hit)
        if widening and len(all_mi):   # the tightest gate that confirmed the entity
            tightest = np.full(n_model, np.inf)
            np.minimum.at(tightest, all_mi, widening[0])
            hit[confirmed] = rule.confirmation(tightest[confirmed])
        change = np.where(confirmed, hit, np.where(verified, rule.image_confirmation or 0.0,
                                                   np.where(missed, rule.miss(rate), 0.0)))
        self.log_odds = np.minimum(self.log_odds + change + rule.contradiction * contradicted, logit(rule.ceiling))
        self.observations = self.observations + confirmed
        self.views = self.views + (confirmed | expected)
        self.last_confirmed = np.where(confirmed | verified, self.frame, self.last_confirmed)
        n_merged = self._consolidate(*candidates)
        # pruning of the old entities, and the new ones appended, in one rebuild of the arrays
        # (a new entity corresponded to nothing: it can be neither pruned nor a duplicate yet)
        confidence = self.confidence
        stale = (confidence < 0.5) & (self.frame - self.last_confirmed >= rule.tentative_frames)
        alive = (confidence >= rule.floor) & ~stale
        n_pruned = int((~alive).sum()) - n_merged
        fresh = np.ones(n_obs, bool)
        fresh[oi] = False
        n_new = int(fresh.sum())
        if n_pruned or n_merged or n_new:
            index, new = np.flatnonzero(alive), np.flatnonzero(fresh)
            self.entities = kind.concatenate(kind.select(self.entities, index), kind.select(observed, new))
            if rule.static_margin is not None:
                first_sensed, first = kind.essentials(kind.select(sensed, new)), kind.essentials(kind.select(observed, new))
                if self.origin is None:
                    self.origin_sensed, self.origin = first_sensed, first
                else:
                    self.origin_sensed = kind.concatenate(kind.select(self.origin_sensed, index), first_sensed)
                    self.origin = kind.concatenate(kind.select(self.origin, index), first)
            self.log_odds = np.concatenate([self.log_odds[index], np.full(n_new, logit(rule.initial))])
            self.observations = np.concatenate([self.observations[index], np.ones(n_new, np.int64)])
            self.views = np.concatenate([self.views[index], np.zeros(n_new, np.int64)])
            self.last_confirmed = np.concatenate([self.last_confirmed[index], np.full(n_new, self.frame)])
            self.static_sum = np.concatenate([self.static_sum[index], np.zeros(n_new)])
        self.frame += 1
        return StepStats(observed=n_obs, confirmed=int(confirmed.sum()), missed=int(missed.sum()), new=n_new,
                         pruned=n_pruned, merged=n_merged, size=len(self), accepted=int((self.log_odds >= 0).sum()),
                         contradicted=int(contradicted.sum()), image_confirmed=int(verified.sum()))

    def _image_confirmed(self, T_model_observed: np.ndarray, context: Any, candidates: np.ndarray) -> np.ndarray:
        """(N,) bool: of the ``candidates`` (N,) bool, the entities whose place the frame's images show
        (the entity type's ``image_confirmed``, given each entity's first observation held still in the
        sensor's frame); none where ``image_confirmation`` is off or the type has no such test."""
        kind = self.entity_type
        if self.rule.image_confirmation is None or self.origin_sensed is None or not candidates.any() \
                or not hasattr(kind, "image_confirmed"):
            return np.zeros(len(self), bool)
        return kind.image_confirmed(self.entities, kind.transform(self.origin_sensed, T_model_observed), context,
                                    candidates)

    def _static(self, observed: E, T_model_observed: np.ndarray, held: np.ndarray) -> np.ndarray:
        """(N,) bool: model entities that this frame's ``observed`` (in the model's frame) show staying
        put in the sensor's frame rather than in the model's: the best cost of an observation with
        the entity's first observation held still in the sensor's frame (``origin_sensed`` moved by
        this frame's ``T_model_observed``) is lower by ``static_margin`` than ``held`` (N,), the best
        cost with the entity where the model has it (inf: none). Only where the entity's first
        observation held still in the sensor's and in the model's frame differ by more than the
        margin: where the object has not moved since, the frame cannot tell. Also adds this frame's
        difference to ``static_sum`` and marks the entities whose sum exceeds ``static_evidence``
        (module docstring, step 2)."""
        rule, kind = self.rule, self.entity_type
        static = np.zeros(len(self), bool)
        if rule.static_margin is None or self.origin is None or kind.size(observed) == 0 or len(self) == 0:
            return static
        still = kind.transform(self.origin_sensed, T_model_observed)
        candidates = np.flatnonzero(~(kind.pair_cost(still, self.origin) <= rule.static_margin))
        if len(candidates) == 0:
            return static
        best = np.full(len(candidates), np.inf)
        _, j, cost = kind.correspondences(observed, kind.select(still, candidates))[:3]  # the metric is symmetric
        np.minimum.at(best, j, cost)
        static[candidates] = best + rule.static_margin < held[candidates]
        if rule.static_evidence is not None:
            here = held[candidates]
            gain = np.isfinite(best) - np.isfinite(here).astype(float)   # one place only shows it: +-1
            both = np.isfinite(best) & np.isfinite(here)
            gain[both] = np.clip(here[both] - best[both], -1.0, 1.0)
            self.static_sum[candidates] += gain
            static[candidates] |= self.static_sum[candidates] > rule.static_evidence
        return static

    def consolidated(self, i: np.ndarray, j: np.ndarray, same) -> "Accumulator[E]":
        """A copy of this accumulator with the candidate pairs (i, j) (N,) int that ``same(accumulator, i,
        j) -> (ok (N,) bool, cost (N,))`` accepts merged as ``_consolidate`` merges duplicates, and the
        absorbed entities dropped; this one is left as it is (the running accumulation goes on). Without
        candidates, this one itself."""
        if len(i) == 0:
            return self
        copy = self._selected(np.arange(len(self)))
        return copy._selected(np.flatnonzero(np.isfinite(copy.log_odds))) if copy._consolidate(i, j, same=same) \
            else copy

    def _selected(self, index: np.ndarray) -> "Accumulator[E]":
        """A new accumulator of the entities at ``index`` (K,) int, every per-entity state in new arrays."""
        kind = self.entity_type
        out = Accumulator(kind, kind.select(self.entities, index), self.rule)
        out.log_odds, out.observations = self.log_odds[index], self.observations[index]
        out.views, out.last_confirmed, out.frame = self.views[index], self.last_confirmed[index], self.frame
        out.static_sum = self.static_sum[index]
        if self.origin is not None:
            out.origin, out.origin_sensed = kind.select(self.origin, index), kind.select(self.origin_sensed, index)
        return out

    def _consolidate(self, i: np.ndarray, j: np.ndarray, rounds: int = 3, same=None) -> int:
        """Merge model entities (candidate pairs i, j) that the entity type deems the same:
        the more confident one absorbs the other, keeping the larger confidence, the sum of
        observations and the larger static evidence (``static_sum``: either having looked still is
        reason to suspect the one thing they are). Without this, a duplicate would take the
        observations of the entity it doubles (merging is one-to-one) and both
        would be punished in turn. Candidates are the entities that corresponded
        to one observation: only those can have become duplicates (a new entity
        corresponded to nothing). ``same(self, i, j)``: another test of the pairs than the entity
        type's ``same(entities, i, j)``, asked again each round. Each round merges pairs of which
        no two share an entity (``disjoint_pairs``: one_to_one, whose two sides were apart, let an entity win one merge
        and lose another, or absorb two losers of which numpy's repeated-index += kept one's
        observations and information); up to ``rounds`` rounds take the rest of a group of three or
        more (merging them in one frame, as before, keeps ``make motion``'s figures)."""
        merged = 0
        for _ in range(rounds):
            alive = np.isfinite(self.log_odds[i]) & np.isfinite(self.log_odds[j])
            i, j = i[alive], j[alive]
            if len(i) == 0:
                break
            ok, cost = same(self, i, j) if same else self.entity_type.same(self.entities, i, j)
            i, j, cost = i[ok], j[ok], cost[ok]
            if len(i) == 0:
                break
            keep = disjoint_pairs(i, j, cost)
            stronger = self.log_odds[i[keep]] >= self.log_odds[j[keep]]
            winner, loser = np.where(stronger, i[keep], j[keep]), np.where(stronger, j[keep], i[keep])
            self.entities = self.entity_type.merge(self.entities, self.entities, winner, loser, None)
            self.log_odds[winner] = np.maximum(self.log_odds[winner], self.log_odds[loser])
            self.observations[winner] += self.observations[loser]
            self.views[winner] = np.maximum(self.views[winner], self.views[loser])
            self.last_confirmed[winner] = np.maximum(self.last_confirmed[winner], self.last_confirmed[loser])
            self.static_sum[winner] = np.maximum(self.static_sum[winner], self.static_sum[loser])
            self.log_odds[loser] = -np.inf  # removed with the pruned ones, in one copy
            merged += len(loser)
        return merged
