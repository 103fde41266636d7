"""Run the benchmarks: ``python -m benchmarks [--quick] [--json PATH]`` (repository root)."""

from .runner import main

if __name__ == "__main__":  # worker processes re-import this module: they must not run it
    main()
