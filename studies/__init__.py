"""One module per paper figure or experiment, the CLI, plotting and the reproduction report."""

