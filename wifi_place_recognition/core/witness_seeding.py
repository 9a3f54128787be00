"""
When the witness proposes a pose to seed the localiser with (ROS-free).

The fused pose, when it is sure (position standard deviation at most
``sure_sd``, yaw's at most ``sure_yaw_sd``): at start-up, while no
localiser message has been heard, and when the localiser is lost; at most
one per ``holdoff`` seconds after one was sent. The witness asks only
while the fused pose is on the survey (:mod:`.witness`).
"""

import math


class Seeding:
    """The seeding policy: which fused pose to propose, and when."""

    def __init__(self):
        self.last_sent = -math.inf

    def propose(self, pose, heard, judgement, params):
        """
        Return why to send the fused ``pose``, or '' (none).

        ``heard``: a localiser message arrived (even a refused one);
        ``judgement``: the verdict the pose was just judged with.
        """
        p = params
        sure = pose.sd <= p.sure_sd and pose.yaw_sd <= p.sure_yaw_sd
        if not sure or pose.stamp - self.last_sent < p.holdoff:
            return ''
        if not heard:
            return 'start-up: no localiser pose yet'
        if judgement.ok is False:
            return f'lost: {judgement.reason}'
        return ''

    def sent(self, stamp):
        """Say that a proposed seed was sent at ``stamp``."""
        self.last_sent = float(stamp)
