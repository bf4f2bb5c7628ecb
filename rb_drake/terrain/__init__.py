"""Terrain from real data: polygon files, meshes and point clouds turned into caves."""
