"""Visual odometry: tracking, keyframes, relocalisation, loop closure and the pose graph."""
