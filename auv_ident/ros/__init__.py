"""ROS layer: the only place rclpy and *_msgs appear (message building, the node toolkit, the
simulator, identifier, record and play nodes, the load test)."""
