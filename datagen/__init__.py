"""datagen: a dataset factory for dexterous robot hands.

Data flows one way: manifest -> objects -> synthesis -> evaluation -> shards.
Subpackages: ``datagen.wrench`` (grasp/task wrench spaces, epsilon metrics).
Importing any of them has no side effects.
"""

__version__ = "0.1.0"
