"""Whether judging the buffered samples now could decide anything: the online monitor's cheap per-sample test.

input: the ``OnlineMonitor`` (its scenario, its buffered samples, the state of its heads and checks) -> output:
``Quiet.loud()``, the streams whose buffered samples can make a check or obligation final if judged now (none: the
update may leave them buffered and return no decision, exactly as judging them would have; ``due`` then names a
stream whose tested samples are judged at this update, one stream per update, ``batch`` at a time; for the pose
samples, whether only the trajectory semantics or only the two semantics can: the timed run and the per-sample
checks, the nominal samples and the tube then wait for the next update, so that an update judges less at once).
Judging them later, together with the samples that follow, gives the same verdicts and the same decision times (the
monitor's verdicts do not depend on the batching), so decisions come at the same ``update`` as when every call
judges.

The test is scalar (plain floats, a few operations per sample) and conservative: any doubt -- a value within
``EPS`` of a limit, a NaN, a duplicate that disagrees, a formula or scenario it does not cover -- says "not quiet".
Before close a check is decided only by failing, an obligation only by one of its leaf windows (a ``Head`` interval
only shrinks, so a Boolean combination's verdict changes only when a leaf's does). So a batch is quiet when:

* workspace and obstacle clearance: no new sample's margin (``verify.geometry``) is below ``EPS``;
* tube: every new pose sample that the next judging can match (a nominal sample at or after it has arrived) is
  within the tube radius plus tolerance (less ``EPS``) of every nominal sample within the matching distance;
* input box: every new command is inside the box (``verify.checks.check_input_box``) by ``EPS``;
* formula, trajectory semantics: for each leaf ``F_I phi`` / ``G_I phi`` not decided and whose window is not complete
  (``phi`` without temporal operators), ``phi`` is not true (``F``) / false (``G``) within ``EPS`` at a new sample
  whose span since the previous sample meets the window, and no new sample reaches the window's end. A gap between
  samples cannot decide it alone: its bounds (``verify.geometry.gap_bounds``: mid-value -/+ half the step, the step
  at least the distance travelled) exceed 0 only where the 1-Lipschitz margins exceed 0 at both ends, and Kleene's
  and / or / not keep that, so the sample ending the gap shows it too;
* formula, timed-run semantics: no new sample changes the set of regions containing the robot (a new entry) and
  no window end is reached.

Formulas with a temporal operator under a window, signal atoms, polygon regions or a polygon workspace are not
covered: the monitor then judges at every ``update`` as before.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from tubempc.mitl import Always, And, Atom, Const, Eventually, Formula, Implies, Not, Or
from verify.checks import INPUT_COMPONENTS, INPUT_TOLERANCE
from verify.online.heads import BoolHead, Head, OfflineHead, StreamHead, WindowHead

if TYPE_CHECKING:
    from verify.online.monitor import OnlineMonitor

__all__ = ["EPS", "EVERY_STREAM", "MAX_WAITING", "POSE_RUN", "POSE_TRAJECTORY", "QUIET_BATCH", "Quiet"]

#: how close to a limit (m, or the command's unit) a value must stay away for a batch to be quiet: far above the
#: rounding differences between this scalar arithmetic and the vectorised judging
EPS = 1e-6
#: slack (ns) on a window's end: the timed run rounds its times through seconds
_END_SLACK_NS = 1_000
#: quiet samples of one stream judged together (fewer if ``max_pending`` is lower): one stream per update, so that
#: an update pays at most one stream's fixed judging cost, and that cost is shared by this many samples
QUIET_BATCH = 256
#: at most this many pose samples wait for an update that judges (a bound on memory should a stream stall the others)
MAX_WAITING = 2 * QUIET_BATCH

#: the buffered streams an update may judge
EVERY_STREAM = frozenset({"pose", "nominal", "cmd"})
#: instead of "pose": the pose samples judged now for the trajectory semantics only, their timed run and per-sample
#: checks at the next update (those cannot decide anything now) ...
POSE_TRAJECTORY = "pose:trajectory"
#: ... or for both semantics now, their per-sample checks at the next update
POSE_RUN = "pose:run"
#: what judging a pose sample now can decide (``Quiet._tested``): a window of the trajectory semantics, the timed
#: run, a per-sample check (workspace, obstacle clearance) -- or anything
_WINDOW, _RUN, _CHECKS = 1, 2, 4
_ANY = _WINDOW | _RUN | _CHECKS
_POSE_AND_NOMINAL = frozenset({"pose", "nominal"})
_CMD = frozenset({"cmd"})
_NONE: frozenset[str] = frozenset()

Value = Callable[[list[float]], float]


def _source(f: Formula, rows: dict[str, list[int]]) -> str | None:
    """``f`` without temporal operators as a Python expression of the discs' margins ``mg`` (an atom's margin is
    its regions' largest, ``verify.geometry.label_margins``); None when ``f`` has a temporal operator."""
    if isinstance(f, Atom):
        ks = rows[f.name]
        return ("-inf" if not ks else f"mg[{ks[0]}]" if len(ks) == 1
                else "max(" + ", ".join(f"mg[{k}]" for k in ks) + ")")
    if isinstance(f, Const):
        return "inf" if f.value else "-inf"
    if isinstance(f, Not):
        a = _source(f.arg, rows)
        return None if a is None else f"-({a})"
    if isinstance(f, And | Or):
        parts = [_source(g, rows) for g in f.args]
        if any(p is None for p in parts):
            return None
        texts = [p for p in parts if p is not None]
        return texts[0] if len(texts) == 1 else ("min(" if isinstance(f, And) else "max(") + ", ".join(texts) + ")"
    if isinstance(f, Implies):
        a, b = _source(f.left, rows), _source(f.right, rows)
        return None if a is None or b is None else f"max(-({a}), {b})"
    return None


def _value_of(f: Formula, rows: dict[str, list[int]]) -> Value | None:
    """``f`` without temporal operators -> its robustness at a sample from the discs' margins (None: temporal).
    Compiled from the parsed formula (names become indexes), so evaluating it is one Python expression."""
    src = _source(f, rows)
    if src is None:
        return None
    fn: Value = eval(compile(f"lambda mg: {src}", "<quiet>", "eval"), {"inf": math.inf, "max": max, "min": min})
    return fn


def _leaves(h: Head) -> list[Head]:
    if isinstance(h, BoolHead):
        return [leaf for k in h.kids for leaf in _leaves(k)]
    return [h]


class Quiet:
    """The per-sample test of one monitor (see the module docstring); ``refresh`` after every judging."""

    def __init__(self, mon: OnlineMonitor) -> None:
        self.mon = mon
        sc = mon.scenario
        geometry = mon._geometry
        rows = {n: list(r) for n, r in zip(mon._names, geometry.atom_rows, strict=True)}
        self.values: dict[int, Value] = {}
        covered = not mon._feeds and geometry.discs and sc.workspace.polygon is None
        for leaf in _leaves(mon._traj.head):
            if isinstance(leaf, WindowHead):
                assert isinstance(leaf.formula, Eventually | Always)
                value = _value_of(leaf.formula.arg, rows)
                if value is None:
                    covered = False
                else:
                    self.values[id(leaf)] = value
            elif not isinstance(leaf, StreamHead | OfflineHead):
                covered = False
        self.enabled = covered
        self.batch = max(1, min(QUIET_BATCH, mon.max_pending - 8))  # below the pushes' own trigger
        self.block = False  # a nominal sample made unknown: judge at the next update
        regions = [r for r in sc.regions if getattr(r, "polygon", None) is None]
        eta = sc.robot.radius
        # per disc: centre, offset of its margin (verify.geometry: r + eta for unsafe, r - eta otherwise), radius
        self.discs = [(float(r.center[0]), float(r.center[1]), float(off), float(r.radius), bool(r.unsafe))
                      for r, off in zip(regions, geometry.offset.tolist(), strict=True)]
        self.eta = eta
        self.unsafe = list(geometry.unsafe)
        ws = sc.workspace
        # the workspace box shrunk by the robot's radius and EPS: a sample inside it has a margin above EPS
        self.inner_box = (float(ws.x[0]) + eta + EPS, float(ws.x[1]) - eta - EPS, float(ws.y[0]) + eta + EPS,
                          float(ws.y[1]) - eta - EPS)
        limits = sc.inputs
        if limits.model == "holonomic":
            bounds = [float(b) for b in limits.max_abs]
            self.cols = [0, 1, 2]
        else:
            bounds = [float(limits.max_abs[0]), float(limits.max_abs[1]), float(limits.lateral_tolerance)]
            self.cols = [0, 2, 1]
        assert len(INPUT_COMPONENTS[limits.model]) == 3
        self.cmd_limit = [b + INPUT_TOLERANCE - EPS for b in bounds]
        self.tube_limit = mon._checks.tube_radius_m + mon._checks.tol_m - EPS
        self.match_ns = mon._checks.period_ns // 2
        self.refresh()

    def refresh(self, *, keep_tube: bool = False) -> None:
        """After a judging: what is still open, and the samples the next test starts from (``keep_tube``: the pose
        samples were judged without the nominal ones: the tube test goes on where it was)."""
        mon = self.mon
        self.pose_seen = self.cmd_seen = 0
        self.block = False
        # the last sample tested in full: (x, y, how far the robot may move before any tested value can reach its
        # limit, the time from which it must be tested again)
        self.ref: tuple[float, float, float, float] | None = None
        sel = mon._selected
        checks = mon._checks
        self.ws = "workspace" in sel and checks.ws.fail_ns is None
        self.clear = "obstacle_clearance" in sel and bool(self.unsafe) and checks.clear.fail_ns is None
        self.cmd = "input_box" in sel and checks.input.fail is None
        self.tube = "tube" in sel and checks.tube.fail is None
        # no nominal sample yet: none can be matched before the first one arrives, which is then judged at once
        self.tube_wait = self.tube and checks.nominal_seen == 0
        t0 = mon.t0_ns
        self.windows: list[tuple[bool, int, float, Value]] = []  # (G?, window start, end (abs ns), phi)
        ends: list[float] = []
        heads = (([mon._traj.head] if "spec_trajectory" in sel else [])
                 + ([mon._run.head] if "spec_timed_run" in sel else []))
        if t0 is not None and self.enabled:
            for root in heads:
                for leaf in _leaves(root):
                    if not isinstance(leaf, WindowHead) or leaf.decided or leaf.complete:
                        continue
                    end = math.inf if leaf.hi_ns is None else float(t0 + leaf.hi_ns)
                    ends.append(end)
                    if root is mon._traj.head:
                        self.windows.append((leaf.always, t0 + leaf.lo_ns, end, self.values[id(leaf)]))
        self.deadline = min(ends, default=math.inf) - _END_SLACK_NS
        self.run_open = "spec_timed_run" in sel and not mon._run.head.decided
        # the last judged sample (the formula's) and the regions containing it, as the judging saw them
        self.prev_t = mon._prev[0] if mon._prev is not None else None
        ps = mon._run_log.prev_set
        self.prev_key: list[bool] | None = None if ps is None else [bool(v) for v in ps[:, 0].tolist()]
        if keep_tube:
            return
        # tube: the pose samples judged but not matched yet, and the nominal samples they (or later ones) may match
        self.nom_seen = 0
        self.unmatched: deque[tuple[int, float, float]] = deque()
        for t, x, y in checks.tube_pending:
            self.unmatched.extend(zip(t.tolist(), x.tolist(), y.tolist(), strict=True))
        nt, nx, ny = checks.nominal
        last = mon._pose.last_ns
        cut = min(last, self.unmatched[0][0] if self.unmatched else last) - self.match_ns
        k = int(nt.searchsorted(cut)) if nt.size else 0
        self.noms: deque[tuple[int, float, float]] = deque(zip(nt[k:].tolist(), nx[k:].tolist(), ny[k:].tolist(),
                                                               strict=True))

    def loud(self) -> frozenset[str]:
        """The streams whose buffered samples must be judged now for the decisions to come at this update (empty:
        judging now decides nothing; see the module docstring). Each call tests the samples pushed since the last
        one (one per stream, typically). The pose samples are judged with the nominal ones (for the tube)."""
        mon = self.mon
        if (not self.enabled or self.block or mon.t0_ns is None or mon._conflict or mon._late or mon._extra
                or len(mon._pose.t) >= MAX_WAITING):
            return EVERY_STREAM
        nom_t = mon._nom.t
        if nom_t:
            if self.tube_wait:
                return EVERY_STREAM
            if self.nom_seen < len(nom_t):
                k = self.nom_seen
                nx, ny = mon._nom.cols
                self.noms.extend(zip(nom_t[k:], nx[k:], ny[k:], strict=True))
                self.nom_seen = len(nom_t)
        cmd = self.cmd and self.cmd_seen < len(mon._cmd.t) and not self._commands_quiet()
        pose = self._poses_loud() if self.pose_seen < len(mon._pose.t) else 0
        if pose & _CHECKS or (self.tube and self.unmatched and not self._tube_quiet()):
            return EVERY_STREAM if cmd else _POSE_AND_NOMINAL
        if pose:  # what cannot decide anything now waits for the next update (an update judges less at once)
            part = POSE_RUN if pose & _RUN else POSE_TRAJECTORY
            return frozenset({part, "cmd"}) if cmd else frozenset({part})
        return _CMD if cmd else _NONE

    def due(self) -> str | None:
        """After ``quiet``: the stream whose tested samples should be judged now ("pose", "cmd", "nominal"; the
        fullest of those holding ``batch`` samples), or None."""
        mon = self.mon
        pose, cmd, nom, batch = len(mon._pose.t), len(mon._cmd.t), len(mon._nom.t), self.batch
        if pose < batch and cmd < batch and nom < batch:
            return None
        return max((pose, "pose"), (cmd, "cmd"), (nom, "nominal"))[1]

    def judged(self, stream: str) -> None:
        """The tested samples of ``stream`` were judged (deciding nothing): the test goes on from the rest."""
        if stream == "pose":
            self.pose_seen = len(self.mon._pose.t)
        elif stream == "cmd":
            self.cmd_seen = len(self.mon._cmd.t)
        else:
            self.nom_seen = len(self.mon._nom.t)

    def _commands_quiet(self) -> bool:
        cmd = self.mon._cmd
        u0, u1, u2 = (cmd.cols[c] for c in self.cols)
        l0, l1, l2 = self.cmd_limit
        for k in range(self.cmd_seen, len(cmd.t)):
            if not (abs(u0[k]) <= l0 and abs(u1[k]) <= l1 and abs(u2[k]) <= l2):  # also NaN
                return False
        self.cmd_seen = len(cmd.t)
        return True

    def _poses_loud(self) -> int:
        """What the pose samples pushed since the last test can decide if judged now (0: nothing): each is near the
        last sample tested in full (every margin tested is 1-Lipschitz in the position, so none has come within EPS
        of its limit, no region was entered or left, no window argument changed sides) or tested in full
        (``_tested``). Once a part can decide, the later samples are tested for the other parts only."""
        mon = self.mon
        pt, (px, py) = mon._pose.t, mon._pose.cols
        hypot, isfinite = math.hypot, math.isfinite
        prev_t, ref, deadline = self.prev_t, self.ref, self.deadline
        unmatched = self.unmatched if self.tube and not self.tube_wait else None
        loud = 0
        for i in range(self.pose_seen, len(pt)):
            t, x, y = pt[i], px[i], py[i]
            if prev_t is None or t >= deadline or not (isfinite(x) and isfinite(y)):
                return self._loud_from(i)
            if ref is None or t >= ref[3] or not hypot(x - ref[0], y - ref[1]) < ref[2]:
                found, ref = self._tested(t, x, y, prev_t, loud)
                loud |= found
                if loud & _CHECKS:
                    return self._loud_from(i)
            if unmatched is not None:
                unmatched.append((t, x, y))
            prev_t = t
        self.prev_t, self.ref = prev_t, ref
        self.pose_seen = len(pt)
        return loud

    def _loud_from(self, i: int) -> int:
        """The pose sample ``i`` can decide anything: the pose samples are judged now in full, so the tube test
        takes it and those after it too."""
        if self.tube and not self.tube_wait:
            mon = self.mon
            pt, (px, py) = mon._pose.t, mon._pose.cols
            self.unmatched.extend(zip(pt[i:], px[i:], py[i:], strict=True))
        return _ANY

    def _tested(self, t: int, x: float, y: float, prev_t: int, skip: int
                ) -> tuple[int, tuple[float, float, float, float] | None]:
        """The full test of one sample for the parts not in ``skip``: the parts it can decide, and (if some room
        is left) the reference the next samples are compared with: (x, y, how far the robot may move before any
        tested value can reach its limit, the time from which it must be tested again)."""
        x0, x1, y0, y1 = self.inner_box
        if self.ws and not (x0 <= x <= x1 and y0 <= y <= y1):  # workspace margin below EPS
            return _CHECKS, None
        slack = min(x - x0, x1 - x, y - y0, y1 - y) if self.ws else math.inf
        found, room, mg = self._discs_room(x, y, skip)
        if found & _CHECKS:
            return found, None
        slack = min(slack, room)
        until = self.deadline
        if not (skip | found) & _WINDOW:
            for always, lo, hi, value in self.windows:
                v = value(mg)
                margin = (v - EPS) if always else (-EPS - v)  # how far the argument is from deciding it
                if margin > 0:
                    slack = min(slack, margin)
                elif t >= lo and prev_t + 1 <= hi:  # the sample or the gap before it is in the window
                    found |= _WINDOW
                    break
                else:  # the window has not started: test again when it does
                    until = min(until, lo)
        return found, ((x, y, slack, until) if slack > 0 else None)

    def _discs_room(self, x: float, y: float, skip: int) -> tuple[int, float, list[float]]:
        """Obstacle clearance and (unless ``skip`` has it) the timed run's containing set at one sample: what it
        can decide (a clearance below EPS: the per-sample checks; on a region's boundary or a new containing set:
        the timed run), how far the robot may move before another of those can happen, and every disc's margin
        (complete unless a clearance is below EPS)."""
        eta, clear, hypot = self.eta, self.clear, math.hypot
        run_open = self.run_open and not skip & _RUN
        found = 0
        slack = math.inf
        mg: list[float] = []
        key: list[bool] = []
        for cx, cy, off, r, unsafe in self.discs:
            d = hypot(x - cx, y - cy)
            if unsafe and clear:
                if off - d > -EPS:  # obstacle clearance below EPS
                    return _CHECKS, 0.0, mg
                slack = min(slack, d - off - EPS)
            if run_open:
                c = d + eta - r
                if -EPS <= c <= EPS:  # on a region's boundary: let the judging say which side
                    found, run_open = _RUN, False
                else:
                    key.append(c < 0)
                    slack = min(slack, abs(c) - EPS)
            mg.append(off - d)
        if run_open:
            key.append(False)  # the "position unknown" row: a finite sample
            if key != self.prev_key:  # a new timed-run entry
                found = _RUN
        return found, slack, mg

    def _tube_quiet(self) -> bool:
        """The pose samples the next judging can match are inside the tube against every candidate nominal."""
        noms, unmatched = self.noms, self.unmatched
        if not noms:
            return True
        last_nom = noms[-1][0]
        match, limit, hypot = self.match_ns, self.tube_limit, math.hypot
        while unmatched and unmatched[0][0] <= last_nom:  # in time order: the ones the next judging matches
            t, x, y = unmatched[0]
            while noms[0][0] < t - match:  # too early for this pose sample and any later one
                noms.popleft()
            for nt, nx, ny in noms:  # in time order: those within the matching distance of t
                if nt > t + match:
                    break
                if not hypot(x - nx, y - ny) <= limit:  # also NaN
                    return False
            unmatched.popleft()
        last = self.mon._pose.last_ns
        cut = min(last, unmatched[0][0] if unmatched else last) - match
        while noms and noms[0][0] < cut:  # no later pose sample can match these
            noms.popleft()
        return True
