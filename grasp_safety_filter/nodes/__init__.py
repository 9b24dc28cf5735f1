"""rclpy node shells and their message-level endpoints (the endpoints need no ROS)."""
