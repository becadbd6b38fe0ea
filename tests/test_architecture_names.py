"""One name per concept (docs/design.md §2), held against the source with ``ast``:

* "evidence" is the diagnosis's per-section evidence (``core/diagnosis/evidence.py``) and the
  evidence a sign-off rests on; the storage checks of seals and hashes are ``db/seals.py``
  (``verify_seals``, ``require_sealed``) and the diagnosis's ranking service is
  ``app/services/diagnosis_ranking.py`` (``rank_causes``, imported under its own name);
* a diagnosis candidate (``TrustedCandidate``) has one name field, ``name`` (the JSON keeps
  ``effect`` beside it for readers of the documented contract, docs/diagnosis.md);
* ``to_dict`` takes ``with_signatures=`` (one spelling);
* an audit key ring (``KeyRing``) is built in two homes only: the server's trust (anchor,
  pins, first use) in ``db/trust.py`` and the assessor's keys (``--public-key``,
  ``--trust-fingerprint``, an exported bundle's ``key.json``) in
  ``app/services/audit_trust.py`` (``explicit_ring``, ``bundle_ring``).

Each rule is checked against a planted violation.
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FOLDERS = ("core", "db", "app", "tools")
#: retired spelling → the one name now
RETIRED = {
    "with_signature": "with_signatures",
    "diagnose_evidence_service": "rank_causes",
    "verify_evidence": "verify_seals",
    "require_evidence": "require_sealed",
    "require_evidence_many": "require_sealed_many",
    "_bundle_ring": "bundle_ring",
}
#: the only modules named ``evidence``
EVIDENCE_MODULES = {"core/diagnosis/evidence.py"}
#: the files that may build an audit key ring
KEY_RING_HOMES = {"db/trust.py", "app/services/audit_trust.py", "app/services/audit_checks.py"}


def _sources(root: Path) -> dict[str, ast.Module]:
    return {str(p.relative_to(root)): ast.parse(p.read_text(encoding="utf-8"))
            for folder in FOLDERS for p in sorted((root / folder).rglob("*.py"))}


def _identifiers(tree: ast.AST) -> set[tuple[str, int]]:
    out = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Name):
            out.add((n.id, n.lineno))
        elif isinstance(n, ast.Attribute):
            out.add((n.attr, n.lineno))
        elif isinstance(n, ast.keyword) and n.arg:
            out.add((n.arg, n.value.lineno))
        elif isinstance(n, ast.arg):
            out.add((n.arg, n.lineno))
        elif isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            out.add((n.name, n.lineno))
        elif isinstance(n, ast.alias):
            out.update({(n.name.rsplit(".", 1)[-1], n.lineno),
                        ((n.asname or ""), n.lineno)})
    return out


def name_violations(root: Path = ROOT) -> list[str]:
    """Every retired spelling, stray ``evidence`` module, second candidate name field and
    key ring built outside its home, as ``path:line: what``."""
    out = []
    for rel, tree in _sources(root).items():
        if Path(rel).stem == "evidence" and rel not in EVIDENCE_MODULES:
            out.append(f"{rel}:1: a module named evidence (seals: db/seals.py)")
        for name, line in sorted(_identifiers(tree)):
            if name in RETIRED:
                out.append(f"{rel}:{line}: {name} (say {RETIRED[name]})")
        for n in ast.walk(tree):
            if isinstance(n, ast.ClassDef) and n.name == "TrustedCandidate":
                fields = [s.target.id for s in n.body
                          if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)]
                if "effect" in fields:
                    out.append(f"{rel}:{n.lineno}: TrustedCandidate.effect beside .name")
            if (isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
                    and n.func.id == "KeyRing" and rel not in KEY_RING_HOMES):
                out.append(f"{rel}:{n.lineno}: KeyRing built outside "
                           "app/services/audit_trust.py")
    return out


def test_one_name_per_concept():
    found = name_violations()
    assert found == [], "\n".join(found)


def test_name_rules_fail_on_planted_violations(tmp_path):
    planted = {
        "db/evidence.py": "def verify_evidence(session):\n    return []\n",
        "core/diagnosis/result.py": """
            class TrustedCandidate:
                effect: str
                name: str
            """,
        "app/services/diagnosis.py": """
            from railval.app.services.diagnosis_ranking import rank_causes as diagnose_evidence_service

            def show(c):
                return c.to_dict(with_signature=True)
            """,
        "app/services/audit.py": """
            from railval.app.services.audit_checks import KeyRing

            def ring():
                return KeyRing({}, "--public-key")
            """,
    }
    for rel, text in planted.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(textwrap.dedent(text), encoding="utf-8")
    found = name_violations(tmp_path)
    assert sorted(found) == sorted([
        "db/evidence.py:1: a module named evidence (seals: db/seals.py)",
        "db/evidence.py:1: verify_evidence (say verify_seals)",
        "core/diagnosis/result.py:2: TrustedCandidate.effect beside .name",
        "app/services/diagnosis.py:2: diagnose_evidence_service (say rank_causes)",
        "app/services/diagnosis.py:5: with_signature (say with_signatures)",
        "app/services/audit.py:5: KeyRing built outside app/services/audit_trust.py",
    ]), found
