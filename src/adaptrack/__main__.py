"""``python -m adaptrack`` runs the command-line interface.

An interrupt while the command is still importing (numba, pandas and the kernels take
seconds on a loaded machine) ends it as one inside the command does: ``error: interrupted``
and status 130, not a death by the signal.
"""

import sys

try:
    from .cli import main
except KeyboardInterrupt:
    print("error: interrupted", file=sys.stderr)
    raise SystemExit(130) from None

if __name__ == "__main__":  # worker processes re-import this module: they must not run the CLI
    main()
