"""Paper reproductions (``make reproduce``): run a paper scenario, print the table ``adcs
report`` prints for its bag (:mod:`adcs_nodes.tools.analyse.papers`, by the scenario's name)."""
from __future__ import annotations

import os
import subprocess
import sys
from typing import List, Optional, Sequence, Tuple

from adcs_nodes.tools.analyse import papers
from adcs_nodes.tools.analyse.papers import Row

#: Scenario name -> extra report sections ``[(title, markdown)]``.
SECTIONS = {'paper000_control', 'paper000_control_misaligned'}


def expectations_for(bag: str) -> Tuple[Optional[str], List[Row]]:
    """``(scenario name, rows)`` of the paper table of ``bag`` (any engine's bag)."""
    return papers.rows_for_bag(bag)


def sections_for(bag: str) -> List[Tuple[str, str]]:
    """Extra report sections of ``bag``'s scenario (paper 000's sensitivity study)."""
    from adcs_nodes.tools.bagfile import bag_scenario
    if (bag_scenario(bag) or {}).get('name') not in SECTIONS:
        return []
    from adcs_nodes.tools.analyse.paper000_sensitivity import sensitivity_markdown
    return [('Sensitivity of the hold accuracy', sensitivity_markdown())]


def table_text(name: Optional[str], rows: Sequence[Row]) -> str:
    """``<name>: paper vs measured`` and the table ``adcs report`` prints."""
    return '\n'.join([f'{name}: paper vs measured', ''] + papers.table_lines(rows)) + '\n'


def record(scenario: str, bag: str, engine: str = 'graph', cwd: Optional[str] = None,
           sets: Sequence[str] = (), timeout_s: float = 3600.0) -> subprocess.CompletedProcess:
    """``adcs run SCENARIO --record BAG --engine ENGINE --quiet`` in a child process."""
    cmd = [sys.executable, '-m', 'adcs_nodes.tools.cli', 'run', scenario, '--record', bag,
           '--engine', engine, '--quiet']
    for item in sets:
        cmd += ['--set', item]
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout_s)


def reproduce(scenario: str, bag: str, engine: str = 'graph', figures: Optional[str] = None,
              cwd: Optional[str] = None, log=print, sets: Sequence[str] = ()
              ) -> Tuple[Optional[str], List[Row]]:
    """Record ``scenario`` (with ``--set`` ``sets``) into ``bag``, print its paper table (and
    draw its figures); ``(name, rows)``, RuntimeError when the run failed."""
    proc = record(scenario, bag, engine, cwd, sets)
    if proc.returncode != 0:
        raise RuntimeError(f'adcs run {os.path.basename(scenario)} exited '
                           f'{proc.returncode}:\n{proc.stdout}{proc.stderr}')
    name, rows = expectations_for(bag)
    log('\n' + table_text(name + (f' --set {" ".join(sets)}' if sets and name else ''), rows))
    if figures:
        for path in papers.figures_for_bag(bag, figures):
            log(f'  figure: {path}')
    return name, rows


def failed(rows: Sequence[Row]) -> List[Row]:
    """The rows that compare with the paper and miss (FAIL)."""
    return [r for r in rows if papers.is_counted(r[3]) and not r[3]]
