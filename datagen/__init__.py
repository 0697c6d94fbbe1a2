"""datagen: a dataset factory for dexterous robot hands.

Data flows one way: manifest -> objects -> synthesis -> evaluation -> shards.
Subpackages: ``datagen.wrench`` (grasp/task wrench spaces, epsilon metrics).
Importing any of them has no side effects.
"""

import logging

__version__ = "0.1.0"

# Library diagnostics go to the "datagen" logger (modules log to its children, datagen.<module>);
# silent unless the application configures logging (the CLI does).
logging.getLogger("datagen").addHandler(logging.NullHandler())
