"""The `vstig` command line (installed as the `vstig_cli` package)."""
