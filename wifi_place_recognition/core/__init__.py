"""The ROS-free, torch-free core: scan mapping, preprocessing, the numpy model, its file."""
