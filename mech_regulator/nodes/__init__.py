"""ROS 2 nodes (rclpy): thin layers over the core that exchange a machine's and a governor's signals
over topics (machine_node, governor_node, scenario_node, recorder_node) and the main job that runs
them together. Nothing in the physics core imports this package."""
