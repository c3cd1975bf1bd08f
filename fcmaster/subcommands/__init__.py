"""The CLI's subcommands, one module each; `fcmaster.cli` parses arguments and maps errors."""
