"""Grasp and task wrench spaces: the paper's differentiable GWS boundary estimator.

Public API (shapes: ``...`` batch, ``m`` contacts, ``K`` directions; positions in metres,
normals unit and pointing into the object, wrenches ``[force, torque]``):

* :func:`grasp_wrench_boundary` ``(..., K, 6)`` points on the GWS boundary (eqs. 4-6, CPN, SFC);
* :func:`support_value` ``(..., K)`` the exact support function;
* :func:`sample_directions` ``(K, 6)`` uniform directions on the 5-sphere;
* :func:`epsilon_metric`, :func:`task_epsilon` ``(...)`` the metrics of eq. 3;
* :func:`task_wrench_support` ``(..., K, 6)`` the TWS support mapping (eq. 7);
* :func:`task_energy` ``(...)`` the cosine task energy (eq. 8) and its L2 ablation;
* :func:`pinch_antipodal_error` ``(...)`` a two-contact pinch's normals against its axis (not
  in the paper; two-finger precision tasks).
"""

from datagen.wrench.antipodal import pinch_antipodal_error
from datagen.wrench.epsilon import EpsilonSearch, epsilon_metric, task_epsilon
from datagen.wrench.gws import grasp_matrix, grasp_wrench_boundary, sample_directions, support_value
from datagen.wrench.tws import task_energy, task_wrench_support

__all__ = [
    "EpsilonSearch",
    "epsilon_metric",
    "grasp_matrix",
    "grasp_wrench_boundary",
    "pinch_antipodal_error",
    "sample_directions",
    "support_value",
    "task_energy",
    "task_epsilon",
    "task_wrench_support",
]
