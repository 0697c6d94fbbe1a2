"""datagen: a dataset factory for dexterous robot hands.

Data flows one way: manifest -> objects -> synthesis -> evaluation -> shards.
Subpackages: ``datagen.wrench`` (grasp/task wrench spaces, epsilon metrics), ``datagen.hands``,
``datagen.objects``, ``datagen.synth``, ``datagen.eval``, ``datagen.io``, ``datagen.interop``.
Importing them has no side effects, with one guard: a ``MUJOCO_GL`` that would make
``import mujoco`` itself fail (e.g. ``osmesa`` without libOSMesa) is removed from the environment,
with a warning (`datagen.gl.drop_unusable`).
"""

from datagen.gl import drop_unusable as _drop_unusable

__version__ = "0.1.0"

_drop_unusable()
