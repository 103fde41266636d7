"""Speed benchmarks of adaptrack against peer libraries, measured in the same run."""
