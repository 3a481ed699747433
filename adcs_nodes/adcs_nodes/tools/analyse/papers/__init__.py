"""The papers' tables, a module per paper: rows ``(quantity, paper value, measured, verdict)``;
verdict True/False, None (info) or :class:`NotComparable` (counted on its own)."""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

#: Verdict of an information row (no paper value to compare with).
INFO = None


@dataclass(frozen=True)
class NotComparable:
    """Verdict of a paper claim this run cannot check (``reason``); False, never a pass."""

    reason: str

    def __bool__(self) -> bool:
        return False


#: One table row: (quantity, paper value, measured, verdict).
Row = Tuple[str, str, Any, Any]

#: Scenario name -> (module in this package, check function ``f(topics, sc) -> rows``).
CHECKS: Dict[str, Tuple[str, str]] = {
    'paper000_estimation': ('paper000', 'check_estimation'),
    'paper000_control': ('paper000', 'check_control'),
    'paper000_control_misaligned': ('paper000', 'check_control_stress'),
    'paper001_mpi': ('paper001', 'check'),
    'paper001_mpi_two_wings': ('paper001', 'check_two_wings'),
    'paper003_slew': ('paper003', 'check'),
    'paper004_yaw': ('paper004', 'check'),
}


def module_for(name: Optional[str]) -> Optional[Any]:
    """The paper module of scenario ``name`` (None when it reproduces no paper)."""
    spec = CHECKS.get(name or '')
    return importlib.import_module(f'{__name__}.{spec[0]}') if spec else None


def check_for(name: Optional[str]) -> Optional[Callable[..., List[Row]]]:
    """The check function ``f(topics, sc) -> rows`` of scenario ``name``, or None."""
    module = module_for(name)
    return getattr(module, CHECKS[name][1]) if module is not None else None


def topics_for(name: Optional[str]) -> Tuple[str, ...]:
    """The topics the check of scenario ``name`` reads (empty when none)."""
    module = module_for(name)
    return tuple(module.TOPICS) if module is not None else ()


def rows_for(sc: Dict[str, Any], topics: Dict[str, Dict[int, Any]]) -> List[Row]:
    """The paper rows of scenario ``sc`` from a run's stamped messages (or none)."""
    check = check_for(sc.get('name'))
    return list(check(topics, sc)) if check is not None else []


def rows_for_bag(bag: str) -> Tuple[Optional[str], List[Row]]:
    """``(scenario name, rows)`` of a bag, the paper picked from its ``scenario.yaml``."""
    from adcs_nodes.tools.analyse.papers.series import from_bag
    from adcs_nodes.tools.bagfile import bag_scenario
    sc = bag_scenario(bag)
    if sc is None:
        return None, []
    name = sc.get('name')
    if check_for(name) is None:
        return name, []
    return name, rows_for(sc, from_bag(bag, topics_for(name)))


def figures_for_bag(bag: str, out_dir: str) -> List[str]:
    """The paths of the paper's figures of a bag's run, written into ``out_dir``."""
    from adcs_nodes.tools.analyse.papers.series import from_bag
    from adcs_nodes.tools.bagfile import bag_scenario
    sc = bag_scenario(bag)
    module = module_for((sc or {}).get('name'))
    if module is None or not hasattr(module, 'figures_of'):
        return []
    return module.figures_of(from_bag(bag, module.TOPICS), sc, out_dir)


# ---------------------------------------------------------------------- text
def verdict_text(ok: Any) -> str:
    """``PASS`` / ``FAIL`` / ``info`` / ``not comparable: <reason>``."""
    if isinstance(ok, NotComparable):
        return f'not comparable: {ok.reason}'
    return 'info' if ok is None else ('PASS' if ok else 'FAIL')


def counts(rows: Sequence[Row]) -> Dict[str, int]:
    """Rows per verdict kind: ``pass``, ``fail``, ``info``, ``not_comparable``."""
    out = {'pass': 0, 'fail': 0, 'info': 0, 'not_comparable': 0}
    for row in rows:
        ok = row[3]
        key = ('not_comparable' if isinstance(ok, NotComparable) else 'info' if ok is None
               else 'pass' if ok else 'fail')
        out[key] += 1
    return out


def is_counted(ok: Any) -> bool:
    """True for a PASS/FAIL verdict (a comparison with the paper)."""
    return ok is not None and not isinstance(ok, NotComparable)


def fmt(value: Any) -> str:
    """A measured value as the tables print it (4 significant digits, yes/no)."""
    import numpy as np
    if isinstance(value, bool):
        return 'yes' if value else 'no'
    return f'{float(value):.4g}' if isinstance(value, (float, np.floating)) else str(value)


def _cell(text: Any) -> str:
    return str(text).replace('|', '\\|').replace('\n', ' ')


def table_lines(rows: Sequence[Row]) -> List[str]:
    """The Markdown table of ``rows`` and its count line (what ``adcs report`` prints)."""
    lines = ['| quantity | paper | measured | verdict |', '|---|---|---|---|']
    for name, paper, measured, ok in rows:
        lines.append('| ' + ' | '.join((_cell(name), _cell(paper), _cell(fmt(measured)),
                                        _cell(verdict_text(ok)))) + ' |')
    lines += ['', summary_line(rows)]
    return lines


def summary_line(rows: Sequence[Row]) -> str:
    """``N of M comparisons with the paper pass; ...``."""
    c = counts(rows)
    text = (f'{c["pass"]} of {c["pass"] + c["fail"]} comparisons with the paper pass; '
            f'{c["info"]} rows are information (no paper value)')
    if c['not_comparable']:
        text += (f'; {c["not_comparable"]} not comparable (a paper claim this run cannot '
                 'check; the reason is in the row)')
    return text + '.'
