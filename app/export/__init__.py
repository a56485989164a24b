"""Run exports: MCAP with ROS 2 schemas (Foxglove, ros2 bag), JSON and CSV."""
