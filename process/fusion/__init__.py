"""Fusion of labelled keyframes into a map: label votes per voxel and the TSDF surface."""
