"""Tests of kindyngen.model.robot_model: the robot model every stage reads."""
