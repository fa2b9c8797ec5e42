"""Reading the markdown tables a benchmark prints (shared by the benchmark smoke tests)."""

from __future__ import annotations


def markdown_tables(out: str) -> list[tuple[list[str], list[list[str]]]]:
    """Markdown tables in ``out`` as (header, rows), the separator line dropped."""
    tables, block = [], []
    for line in [*out.splitlines(), ""]:
        if line.startswith("|"):
            block.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif block:
            tables.append((block[0], block[2:]))
            block = []
    return tables
