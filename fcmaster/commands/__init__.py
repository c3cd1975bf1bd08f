"""The CLI's commands, one module each; `fcmaster.cli` parses arguments and maps errors."""
