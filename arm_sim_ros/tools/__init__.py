"""arm-sim and its subcommands, at the top: may import every layer below."""
