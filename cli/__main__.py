"""``python -m cli``: the ``recon`` command without its console script.

``python -m recon`` cannot be offered: the layering rule is that nothing imports ``cli``, and
``recon/__main__.py`` would have to. ``cli`` is the package the import rules allow.
"""

import sys

from cli.main import main

sys.exit(main())
