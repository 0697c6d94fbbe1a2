"""``python -m datagen.gl``: print the offscreen GL backend rendering would use (exit 1 if none)."""

import sys

from datagen.gl import main

sys.exit(main())
