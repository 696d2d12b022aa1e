import os
import sys

# `python -m tofnet` puts the working folder first on sys.path; a spec or plan in it (or a
# stranger's evil module beside one) must not be importable unless named (docs/reliability.md).
# Kept only when tofnet itself was loaded from there (a source checkout without PYTHONPATH).
if sys.path and not getattr(sys.flags, "safe_path", False) and sys.path[0] in ("", os.getcwd()):  # -P: 3.11+
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if os.path.abspath(sys.path[0] or ".") != here:
        del sys.path[0]

from tofnet.cli import main  # noqa: E402

sys.exit(main())
