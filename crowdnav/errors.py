"""``CrowdNavError``: the one base of every exception crowdnav defines.

``except crowdnav.CrowdNavError`` catches whatever crowdnav raises on purpose (a bad scenario or
config file, a damaged checkpoint or results folder, a run that cannot go on), as opposed to a bug.
Each crowdnav exception also keeps the builtin base it always had (``ValueError``,
``RuntimeError``, ``FileExistsError``, ...), so code catching that still catches it. Its message
is one line meant for the person running crowdnav (the command line prints it without a traceback).
"""


class CrowdNavError(Exception):
    """Base of every crowdnav exception (see the module docstring)."""


def install_line(extra: str) -> str:
    """How to install the optional ``extra``, as error messages and help say it: crowdnav is on no package index, so from a clone.

    ``pip install -e ".[orca]" in crowdnav's clone`` (the README's Install section); never the
    package's name with the extra in brackets, which no index can answer.
    """
    return f'pip install -e ".[{extra}]" in crowdnav\'s clone'
