"""The robot model every stage reads: immutable dataclasses with exact numbers (joints, links, placements, inertial parameters)."""
