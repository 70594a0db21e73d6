"""Cuts of a brick octree: level of detail, the error metric and its cut policy, and the bricks a
frame loads."""
