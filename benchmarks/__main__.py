"""Run the benchmarks: ``python -m benchmarks [--quick] [--json PATH]`` (repository root)."""

from .runner import main

main()
