"""Command line shared by the examples: ``--short`` (or GS_EXAMPLES_SHORT=1) for a quick CI run."""
import argparse
import os


def short_mode(doc):
    """Parse the command line of an example whose docstring is ``doc``; True in short mode."""
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--short", action="store_true", help="quick CI run (also: GS_EXAMPLES_SHORT=1)")
    args = parser.parse_args()
    return args.short or os.environ.get("GS_EXAMPLES_SHORT", "0") not in ("", "0")
