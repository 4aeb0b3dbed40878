"""Analysis: experiments, Monte Carlo, results tables and JSON, the report, the benchmark."""
