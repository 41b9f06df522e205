"""Sub-commands of the `linkd` command line; each module has `register(subparsers)`."""
