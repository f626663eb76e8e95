"""Every option and positional argument of every verb has a help text, and every option with
a default other than None says it."""

from __future__ import annotations

import argparse

from cfbmarkov.cli import build_parser


def _verbs():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices.items()


def test_every_argument_has_help_and_states_its_default():
    missing, no_default = [], []
    for name, verb in _verbs():
        for action in verb._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            label = f"{name} {'/'.join(action.option_strings) or action.dest}"
            if not (action.help and action.help.strip()):
                missing.append(label)
                continue
            boolean = isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction))
            if (action.option_strings and action.default is not None and not boolean
                    and not action.required):
                shown = action.help % {"default": action.default, "prog": name}
                if isinstance(action.default, (list, tuple)):
                    values = ("default",)      # written as on the command line (6x38, 10:15)
                else:
                    values = (f"default {action.default}", f"default {action.default:g}"
                              if isinstance(action.default, (int, float)) else "default ")
                if not any(v in shown for v in values):
                    no_default.append(f"{label} (default {action.default!r})")
    assert not missing, f"arguments without help: {missing}"
    assert not no_default, f"options whose help does not state the default: {no_default}"


def test_every_verbs_help_page_opens_with_what_the_verb_does():
    """`cfbmarkov VERB --help` opens (below its usage) with the verb's line of `cfbmarkov
    --help`, as a sentence."""
    parser = build_parser()
    verbs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    said = {action.dest: action.help for action in verbs._choices_actions}
    for name, verb in verbs.choices.items():
        assert said[name], name
        assert verb.description == said[name][0].upper() + said[name][1:] + ".", name
        assert verb.format_help().split("\n\n")[1].replace("\n", " ").startswith(
            said[name][0].upper() + said[name][1:20]), name
