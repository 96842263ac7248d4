"""TUI tests: Pilot tests of the workspace, the real binary in tmux and a pty, the TUI in a browser."""
