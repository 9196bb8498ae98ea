"""The `vstig` commands, one module each, named after the command (`vstig_cli.main` finds them here)."""
