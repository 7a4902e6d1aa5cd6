"""Every reference in the repository points inside it.

A tracked text file may cite the model only as docs/model.md: a section by its number
("docs/model.md §11.2") or an assumption by its label ("docs/model.md A30"). This checks that

* no file cites a document the repository does not have (the old model specification, the
  shared docs folder) or an issue number of a tracker;
* every cited section number is a heading of docs/model.md and every cited label a row of its
  §15 table;
* a file that uses a bare "§" names docs/model.md, and every "§N" in it is a heading there (the
  paper's sections are cited as "Sec. N", so "§" always means docs/model.md).

The patterns below are written so that this file does not match them itself.
"""

from functools import cache
from pathlib import Path
import re
import subprocess

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
MODEL_DOC = 'docs/model.md'

#: (what it means, pattern) of citations that lead outside the repository.
FORBIDDEN = (
    ('the old model specification', re.compile(r'model[-]spec', re.IGNORECASE)),
    ('the shared docs folder', re.compile(r'shared[/]docs', re.IGNORECASE)),
    ('a section of the old specification', re.compile(r'\bspec ?[§]', re.IGNORECASE)),
    ('the paper cited by its old nickname', re.compile(r'\bseed (?:[§]|eq\b)', re.IGNORECASE)),
    ('an issue number', re.compile(r'\bissues?[ ]+#?\d+|\bissues?[ ]*#\d+', re.IGNORECASE)),
)

SECTION = r'\d+(?:\.\d+)?'
ITEM = rf'(?:§{SECTION}|A\d+|sections?\s+{SECTION})'
RANGE = rf'{ITEM}(?:\s*[-–]\s*(?:§?{SECTION}|A\d+))?'
#: "docs/model.md" followed by a list of sections and labels, e.g. "docs/model.md §10, A30",
#: "docs/model.md §6-§7", "docs/model.md sections 2.2-2.4 (A5-A8)".
CITATION = re.compile(rf'docs/model\.md((?:(?:[\s,;()]+|\s+and\s+){RANGE})+)')
CITED_SECTION = re.compile(rf'(?:§|sections?\s+|[-–]\s*)({SECTION})(?![\d.]*\d)')
CITED_LABEL = re.compile(r'\bA(\d+)\b')
BARE_SECTION = re.compile(rf'§\s?({SECTION})(?![\d.]*\d)')


@cache
def _tracked_texts() -> dict[str, str]:
    """Path -> text of every tracked file that is UTF-8 text (binary files are skipped)."""
    try:
        listing = subprocess.run(['git', 'ls-files', '-z'], cwd=REPO_ROOT, capture_output=True,
                                 check=True, timeout=60).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        pytest.skip(f'not a git checkout ({exc})')
    texts = {}
    for name in filter(None, listing.decode().split('\0')):
        path = REPO_ROOT / name
        if not path.is_file():
            continue  # deleted in the work tree, or a submodule
        data = path.read_bytes()
        if b'\0' in data:
            continue
        try:
            texts[name] = data.decode('utf-8')
        except UnicodeDecodeError:
            continue
    return texts


def _model_text() -> str:
    return (REPO_ROOT / MODEL_DOC).read_text(encoding='utf-8')


@cache
def _model_sections() -> frozenset[str]:
    """Section numbers of docs/model.md's headings: '1', '1.1', ..., '15'."""
    return frozenset(re.findall(r'^#{2,4}\s+(\d+(?:\.\d+)?)\.?\s', _model_text(), re.MULTILINE))


@cache
def _model_labels() -> frozenset[int]:
    """Assumption labels n of the rows '| A<n> | ...' of docs/model.md §15."""
    part = re.split(r'^##\s+15\.', _model_text(), maxsplit=1, flags=re.MULTILINE)
    assert len(part) == 2, 'docs/model.md has no section 15 (assumptions)'
    return frozenset(int(n) for n in re.findall(r'^\|\s*A(\d+)\s*\|', part[1], re.MULTILINE))


def _line(text: str, offset: int) -> int:
    return text.count('\n', 0, offset) + 1


def test_model_document_has_its_sections_and_labels():
    sections, labels = _model_sections(), _model_labels()
    assert {'1', '1.1', '15'} <= sections
    assert labels and labels == set(range(1, max(labels) + 1)), 'labels A1..An, none missing'


def test_no_file_cites_a_document_outside_the_repository():
    found = [f'{name}:{_line(text, m.start())}: {what}: {m.group(0)!r}'
             for name, text in _tracked_texts().items()
             for what, pattern in FORBIDDEN
             for m in pattern.finditer(text)]
    assert not found, 'references to documents the repository does not have:\n' + \
        '\n'.join(found)


def test_model_citations_name_existing_sections_and_labels():
    sections, labels = _model_sections(), _model_labels()
    bad, seen = [], 0
    for name, text in _tracked_texts().items():
        for m in CITATION.finditer(text):
            seen += 1
            where = f'{name}:{_line(text, m.start())}: {m.group(0)!r}'
            bad += [f'{where}: no section {n}' for n in CITED_SECTION.findall(m.group(1))
                    if n not in sections]
            bad += [f'{where}: no label A{n}' for n in CITED_LABEL.findall(m.group(1))
                    if int(n) not in labels]
    assert seen > 0, 'no citation of docs/model.md found: is the pattern still right?'
    assert not bad, 'citations of docs/model.md that do not exist:\n' + '\n'.join(bad)


def test_bare_section_signs_refer_to_the_model_document():
    sections = _model_sections()
    bad = []
    for name, text in _tracked_texts().items():
        numbers = [(m.group(1), m.start()) for m in BARE_SECTION.finditer(text)]
        if not numbers:
            continue
        if name != MODEL_DOC and MODEL_DOC not in text:
            bad.append(f'{name}: uses "§" but never names {MODEL_DOC}')
        bad += [f'{name}:{_line(text, at)}: §{n} is no section of {MODEL_DOC}'
                for n, at in numbers if n not in sections]
    assert not bad, '\n'.join(bad)
