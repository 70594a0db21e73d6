"""Acceleration structures: integer grid traversal and min/max block hierarchies."""
