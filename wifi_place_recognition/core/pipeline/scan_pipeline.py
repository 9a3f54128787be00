"""
One scan's path, ROS-free: recognise, place changes, odometry fusion.

:class:`ScanPipeline` is what classifier_node runs and what the
benchmarks run offline (:func:`.filter.trajectory.fuse_offline`): a scan
(AP names, RSSI, stamp) or odometry in, :class:`.outputs.Outputs` out.
A scan is recognised (:class:`.recognizer.PlaceRecognizer`; a scan it
cannot use is rejected and counted, one its model's coverage probability
puts off the survey counted as ``off_survey``), its answer followed by
:class:`.place_changes.PlaceChanges` (the current place, why to re-seed),
and its position either given as it is or, while odometry arrives and
fusion is on, fed to the filter (:class:`.fusion_stage.FusionStage`),
whose poses follow as odometry covers them. With
``initial_pose_on_change``, a pose is due on ``initialpose`` at a change
of place or a jump; while fusing, the filter's first pose from that scan
on in that place (after a change of floor, its start there), and instead
of the scans' jumps, the filter's fresh starts on its floor. A requested
one (:meth:`ScanPipeline.request_initial_pose`) is the next confident
answer's. :meth:`ScanPipeline.use_model` swaps the recognizer's model
between two scans; the fused pose and the current place carry on.
"""

from collections import Counter
import math
import time

import numpy as np

from ..coverage import uncovered
from ..filter.fusion import Fusion
from ..recognizer import OK, Place, PlaceRecognizer
from ..scan import ScanRejected
from .fusion_stage import FusionStage
from .outputs import Outputs, Pose, Rejected
from .place_changes import PlaceChanges

#: Settings of :meth:`ScanPipeline.configure` beyond the recognizer's.
SETTINGS = ('jump_threshold', 'initial_pose_on_change', 'fusion',
            'odom_timeout', 'pose_rate')


class ScanPipeline:
    """
    Scans and odometry in, everything to publish out.

    ``recognizer``: a :class:`.recognizer.PlaceRecognizer` (None: answers
    only, through :meth:`answer`); ``fusion``: the filter (default, with
    a position model: a :class:`.filter.fusion.Fusion` of the model's
    fusion parameters; None without one). ``now`` arguments are the
    caller's clock, the one :meth:`tick` is given.
    """

    def __init__(self, recognizer=None, fusion=None):
        self.recognizer = recognizer
        if fusion is None and recognizer is not None and \
                recognizer.model.position is not None:
            fusion = Fusion(recognizer.model.fusion)
        self.fusion = None if fusion is None else FusionStage(fusion)
        self.changes = PlaceChanges()
        self.initial_pose_on_change = False
        self.counts = Counter(received=0, answered=0, rejected=0, dropped=0,
                              off_survey=0)
        self.last_latency_ms = math.nan
        self._requested = False    # the next confident answer: initialpose
        self._pending = None       # (stamp, reasons, place): a fused one

    def configure(self, jump_threshold=None, initial_pose_on_change=None,
                  fusion=None, odom_timeout=None, pose_rate=None,
                  **recognizer_settings):
        """Change the settings given (None: keep), the recognizer's too."""
        if recognizer_settings:
            self.recognizer.configure(**recognizer_settings)
        if jump_threshold is not None:
            self.changes.jump_threshold = jump_threshold
        if initial_pose_on_change is not None:
            self.initial_pose_on_change = initial_pose_on_change
        if self.fusion is not None:
            self.fusion.configure(odom_timeout, pose_rate, fusion)

    def use_model(self, model, forward=None):
        """
        Recognise the next scans with ``model``; return what it changed.

        Between two scans: no scan is lost or answered twice. The settings
        carry on, and so do the current place and the fused pose (the
        filter and its odometry fit: a new ``fusion`` section applies at the
        next start). The tracked belief carries on when the classes and the
        tracking section are the same, else starts afresh. Raises ValueError
        when ``model`` has a position output and the running one has not,
        or the other way round (what the caller publishes depends on it).
        """
        old = self.recognizer
        problem = swap_problem(old.model, model)
        if problem:
            raise ValueError(problem)
        new = PlaceRecognizer(model, old.min_confidence, old.min_known_aps,
                              old.mapper.max_aps, forward)
        new.tracking_timeout = old.tracking_timeout
        changed = []
        if old.tracker is not None:
            if np.array_equal(model.classes, old.model.classes) and \
                    model.tracking == old.model.tracking:
                new.tracker = old.tracker
            else:
                new.configure(tracking=True)
                changed.append('the tracked belief starts afresh (other '
                               'classes or tracking section)')
        if self.fusion is not None and model.fusion != old.model.fusion:
            changed.append('the fused pose keeps the running odometry fit '
                           '(the new fusion section applies at the next '
                           'start)')
        self.recognizer = new
        return changed

    def request_initial_pose(self):
        """Send the next confident answer's pose on initialpose."""
        self._requested = True

    def set_pose(self, stamp, xy, yaw, sd, yaw_sd, places):
        """
        Start the fused pose at a known pose; return why not, or None.

        ``places``: the (building, floor) the pose's frame can name: one,
        or several (one frame for every floor) of which the current place
        must be one. A refusal names what is wrong; the pose is not used.
        """
        if self.fusion is None:
            return 'the model has no position output: nothing to fuse'
        if not self.fusion.enabled:
            return 'fusion is off'
        places = list(places)
        if not places:
            return 'its frame is that of no place of the model'
        if len(places) > 1:
            if self.changes.place not in places:
                return ('its frame is that of several places, and none is '
                        'the current place yet')
            places = [self.changes.place]
        try:
            self.fusion.set_pose(stamp, xy, yaw, sd, yaw_sd, places[0])
        except ValueError as exc:
            return str(exc)
        except Exception as exc:  # never let the filter stop the caller
            return f'internal error: {exc!r}'
        return None

    def reset(self):
        """Forget the tracked belief and the fused pose; return what was."""
        cleared = []
        if self.recognizer is not None and \
                self.recognizer.tracker is not None:
            self.recognizer.tracker.reset()
            cleared.append('tracked belief')
        if self.fusion is not None and self.fusion.enabled:
            self.fusion.reset()
            cleared.append('fused pose')
        return cleared

    def scan(self, names, rssi, stamp, now, source=None, dropped=0,
             received=None):
        """
        Recognise one scan taken at ``stamp`` (s); return its outputs.

        ``source``: the caller's own stamp, handed back with its poses;
        ``dropped``: scans lost before this one (counted);
        ``received``: when it arrived (:func:`time.perf_counter`, default
        now), the start of its latency.
        """
        received = time.perf_counter() if received is None else received
        self.counts['received'] += 1 + dropped
        self.counts['dropped'] += dropped
        try:
            answer = self.recognizer.classify(names, rssi, stamp)
        except ScanRejected as exc:
            return self._reject(exc.reason, str(exc))
        except Exception as exc:  # never let one scan stop the caller
            return self._reject('internal_error', repr(exc))
        self.last_latency_ms = (time.perf_counter() - received) * 1e3
        self.counts['answered'] += 1
        if answer.coverage is not None:     # the model has a coverage model
            self.counts['off_survey'] += bool(uncovered(answer.coverage))
        return self.answer(answer, stamp, now, source,
                           Outputs(answer, latency_ms=self.last_latency_ms))

    def _reject(self, reason, detail):
        self.counts['rejected'] += 1
        self.counts[f'rejected/{reason}'] += 1
        return Outputs(rejected=Rejected(reason, detail))

    def answer(self, answer, stamp, now, source=None, out=None):
        """Follow one :class:`.recognizer.Place` at ``stamp``; its outputs."""
        out = out or Outputs(answer)
        confident = answer.level == OK
        fusing = self.fusion is not None and self.fusion.active
        out.place_changed, reasons = self.changes.follow(
            answer, confident, jumps=not fusing)
        if answer.position is None:
            return out
        reasons = reasons if self.initial_pose_on_change else []
        if not fusing:
            self._forget_pending()
        if confident and self._requested:
            self._requested = False
            reasons = reasons + ['requested']
        place = (answer.building, answer.floor)
        if not fusing:
            out.poses.append(Pose(stamp, source, answer.position,
                                  answer.position_cov, place,
                                  initial=reasons))
            return out
        if reasons:     # due with the filter's first pose from this scan
            self._pending = (stamp, reasons, place)
        self._add(out, self.fusion.scan(answer, place, confident, stamp,
                                        source, now, out.problems))
        return out

    def odometry(self, stamp, x, y, yaw, now, source=None, what=None):
        """
        Take one odometry pose (odom frame, stamp s, yaw rad); its outputs.

        ``what`` names the message in a refusal (default: its stamp and
        x, y).
        """
        out = Outputs()
        if self.fusion is not None:
            what = what or f'stamp {stamp:.9f}: x {x:g}, y {y:g}'
            self._add(out, self.fusion.odometry(stamp, x, y, yaw, now, source,
                                                what, out.problems))
        return out

    def tick(self, now):
        """Release the scans that waited too long; the pose between scans."""
        out = Outputs()
        if self.fusion is not None:
            self._add(out, self.fusion.tick(now, out.problems))
        return out

    def _forget_pending(self):
        """Fusion stopped before a re-seed went out: a request waits on."""
        if self._pending is not None:
            if 'requested' in self._pending[1]:
                self._requested = True
            self._pending = None

    def _add(self, out, released):
        """
        Add fused poses to ``out``; on initialpose too when a re-seed is due.

        Due: the pending one, or, with ``initial_pose_on_change``, a
        ``relocated`` filter, which with fusion stands for the scans' own
        jumps.
        """
        for pose, relocated in released:
            waiting = self._pending
            if waiting is not None and pose.stamp >= waiting[0] and \
                    pose.place == waiting[2]:
                self._pending, pose.initial = None, waiting[1]
            elif relocated and self.initial_pose_on_change:
                pose.initial = ['the fused pose started afresh']
            out.poses.append(pose)


def swap_problem(running, model):
    """
    Return why ``model`` cannot replace the ``running`` one, or None.

    Either both have a position output or neither: what a caller
    publishes depends on it.
    """
    if (model.position is None) == (running.position is None):
        return None
    has = 'has no' if running.position is None else 'has a'
    this = 'one' if model.position is not None else 'none'
    return (f'the running model {has} position output and this one has '
            f'{this}: restart the node to change that')


def position_answer(xy, sigma=math.nan, place=(0, 0), coverage=None,
                    mismatch=math.nan):
    """
    Return a confident answer at ``xy`` (m) with ``sigma`` (m) on ``place``.

    A position known without recognising a scan (a batch forward pass
    offline) as :meth:`ScanPipeline.answer` takes it; ``coverage``: its
    probability of lying where the survey covers (None: not known);
    ``mismatch``: how unlike its nearest references it sounds, over the
    survey's usual (NaN: not known).
    """
    xy = np.asarray(xy, np.float64)
    return Place(place[0], place[1], 1.0, np.ones(1), 0, 0, 0, OK, '',
                 place[0], place[1], 1.0, xy, np.eye(2) * sigma ** 2, xy,
                 sigma, coverage, mismatch=mismatch)
