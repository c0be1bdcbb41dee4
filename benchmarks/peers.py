"""The peer versions a benchmark's set-up was checked against: another version may change the
meaning of an argument (a stiffness, a compliance, an axis) without an error, and a comparison
with a set-up that no longer matches is worse than none. `require` refuses it, naming both."""

from importlib.metadata import PackageNotFoundError, version


def require(package: str, checked: tuple[str, ...], purpose: str) -> str:
    """The installed version of `package` if it starts with one of `checked` (e.g. "1.19."),
    else SystemExit naming what is installed, what was checked and `purpose`."""
    try:
        installed = version(package)
    except PackageNotFoundError:
        raise SystemExit(f"{purpose} needs {package} ({' or '.join(checked) or 'no version'} "
                         f"checked): pip install {package}") from None
    if not any(installed.startswith(prefix) for prefix in checked):
        raise SystemExit(
            f"{purpose}: {package} {installed} is installed, but this benchmark's set-up was "
            f"checked against {' or '.join(checked) if checked else 'no version of it yet'}; "
            "its results would not mean what the docs say")
    return installed
