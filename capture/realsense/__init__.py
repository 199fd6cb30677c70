"""The only pyrealsense2 user: device and streams, the recording session and its writer thread."""
