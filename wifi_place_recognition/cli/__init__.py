"""The command-line tools: argument parsing and ``main()`` only."""
