"""The one error type the command line turns into a one-line message and exit status 2."""


class InputError(Exception):
    """Bad user input: a file that cannot be read, a malformed value, a wrong option.

    The message is one line and names what is wrong (file, row, key); the CLI prints
    it without a traceback and exits with status 2.
    """
