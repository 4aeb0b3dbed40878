"""ROS 2 nodes: thin layers over the core (parameters, message conversion, core call, publish)."""
