"""
The odometry + WiFi filter (ROS-free, numpy only).

In the pieces of nav2_amcl and robot_localization: the :mod:`.motion`
and :mod:`.sensor` models, :mod:`.particles` (the filter and its
parameters), :mod:`.track_misfit` and :mod:`.mismatch` (how far a scan
is trusted),
:mod:`.fusion` (stamped streams applied in stamp order), :mod:`.pose_spread`
(how sure the pose is), :mod:`.trajectory`
(a run scored offline) and :mod:`.odometry_fit` (the odometry's drift
from a surveyed run); :mod:`.angles` wraps headings.
"""
