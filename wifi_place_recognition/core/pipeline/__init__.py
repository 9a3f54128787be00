"""
The per-scan path (ROS-free): what classifier_node runs, and the benchmarks.

:mod:`.scan_pipeline` (the path: recognise, place changes, fusion),
:mod:`.place_changes` (the current place, when to re-seed a localiser),
:mod:`.fusion_stage` (the odometry fusion on the caller's clock),
:mod:`.outputs` (what each step gives to publish).
"""
