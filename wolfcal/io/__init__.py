"""Capture files: write samples, read samples (own files and plain ROS 2 recordings), recover torn files."""
