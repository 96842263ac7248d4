"""Architecture tests: the rules of the code as tests (import-linter contracts, import cycles, one
definition per default and choice list, the type checker and the linter, engine imports without a
terminal, the registries) and the rules of this test tree (test_test_layout.py). No shared fixtures."""
