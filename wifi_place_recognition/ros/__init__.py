"""The ROS 2 adapters: nodes, their runner, message conversions, the replayer."""
