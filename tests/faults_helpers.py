"""What the test_faults_* modules share: the repository's root, and a command's exit code with its stderr."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _err(capsys, main, argv):
    code = main(argv)
    err = capsys.readouterr().err
    return code, err
