"""Bags: rosbag2 MCAP reader and writer without rosbag2, and bag replay through the session."""
