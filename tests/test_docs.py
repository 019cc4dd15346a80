"""The documentation that is generated stays generated, and the README stays short."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_configuration_page_is_what_the_dataclasses_say():
    """docs/configuration.md is written by gpquad.study.config_reference: a new or changed
    option without its page fails here (regenerate with the command in the message)."""
    from gpquad.study.config_reference import markdown

    page = (ROOT / "docs" / "configuration.md").read_text()
    assert page == markdown(), (
        'docs/configuration.md is stale: python -c "from gpquad.study.config_reference import '
        "markdown; open('docs/configuration.md', 'w').write(markdown())\""
    )


def test_every_option_is_on_the_page():
    import dataclasses

    from gpquad.study.config import EvolutionConfig

    page = (ROOT / "docs" / "configuration.md").read_text()
    missing = [
        f.name
        for f in dataclasses.fields(EvolutionConfig)
        if f.name != "gp" and f"`{f.name}`" not in page
    ]
    assert missing == []


def test_readme_is_short_and_has_the_two_commands():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 200
    assert "gpquad run experiments/quickstart.toml" in readme
    assert 'pip install -e ".[test]" && python -m pytest -q' in readme
