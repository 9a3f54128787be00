"""
When the witness proposes a pose to seed the localiser with (ROS-free).

The fused pose, when it is sure (position standard deviation at most
``sure_sd``, yaw's at most ``sure_yaw_sd``, and the scans of the last
``sure_s`` seconds on average within ``sure_sd`` of its track): at
start-up, while no localiser message has been heard, once it has been
sure for ``startup_sure_s`` seconds without a break, and when the
localiser is lost; at most one per ``holdoff`` seconds after one was
sent; none while the pose is built on scans off the survey (the witness
says so: :mod:`.witness`). A new timeline (a bag or a simulation started
again) starts with a new :class:`Seeding`.

The fused covariance comes from the last few scans' offsets. Scans from
where the survey never went that moved as the robot did drag the pose
along and hold it together, and once they are good again the pose comes
back over tens of seconds, metres off with a narrow covariance: the scans
of the last minute, which include the dragging ones, still lie on average
metres from its track. A young filter's covariance narrows before its
heading is right: a start-up seed, which nothing corrects (no localiser
pose to compare with), waits until the pose has stayed sure; a re-seed
replaces a pose known to be wrong and does not wait.
"""

import math


class Seeding:
    """The seeding policy: which fused pose to propose, and when."""

    def __init__(self):
        self.last_sent = -math.inf
        self.sure_since = None     # stamp since which the pose is sure

    def propose(self, pose, heard, judgement, params, scan_offset,
                off_survey):
        """
        Return why to send the fused ``pose``, or '' (none).

        Called with every fused pose judged (sureness is seen at each
        judgement, on the survey or not). ``heard``: a localiser message
        arrived (even a refused one); ``judgement``: the verdict
        the pose was just judged with; ``scan_offset(since, frame)``: how
        far the scans since then lie from the fused track on average (m;
        None: no scan), asked last; ``off_survey``: why the pose is built
        on scans off the survey ('': it is not; else none is proposed).
        """
        p = params
        sure = pose.sd <= p.sure_sd and pose.yaw_sd <= p.sure_yaw_sd
        if not sure:
            self.sure_since = None
        elif self.sure_since is None:
            self.sure_since = float(pose.stamp)
        if not sure or off_survey or \
                pose.stamp - self.last_sent < p.holdoff:
            return ''
        if not heard:
            if pose.stamp - self.sure_since < p.startup_sure_s:
                return ''
            why = 'start-up: no localiser pose yet'
        elif judgement.ok is False:
            why = f'lost: {judgement.reason}'
        else:
            return ''
        if p.sure_s:
            offset = scan_offset(pose.stamp - p.sure_s, pose.frame)
            if offset is not None and offset > p.sure_sd:
                return ''
        return why

    def sent(self, stamp):
        """Say that a proposed seed was sent at ``stamp``."""
        self.last_sent = float(stamp)
