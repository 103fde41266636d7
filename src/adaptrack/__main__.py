"""``python -m adaptrack`` runs the command-line interface."""

from .cli import main

if __name__ == "__main__":  # worker processes re-import this module: they must not run the CLI
    main()
