"""Quaternion helpers of synthesis: re-exported from `datagen.rotation`, where they live."""

from datagen.rotation import axis_angle_to_quat, matrix_to_quat, quat_multiply, quat_to_matrix, rotate_about

__all__ = ["axis_angle_to_quat", "quat_multiply", "matrix_to_quat", "quat_to_matrix", "rotate_about"]
