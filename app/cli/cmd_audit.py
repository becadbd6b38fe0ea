"""CLI verbs ``audit …`` and ``signoff …`` (docs/audit.md).

``railval audit checkpoint FILE``  write the chain's head (count + hash) to FILE; keep it elsewhere
``railval audit verify [--checkpoint FILE] [--bundle DIR] [--quick] [--json]``
    recompute the chain, every signal blob's SHA-256 and every sign-off's evidence hash (or
    check an exported bundle without the database); names the first break; exit 0 only
    when everything holds, 1 when something does not
    [--witness FILE | --no-witness] [--public-key HEX|FILE] [--trust-fingerprint FP]...:
    trusts the key pinned in the server's configuration directory (or given), prints which
    and from where, and compares with the trust anchor's witnessed head and witness file
``railval audit key [--json]``  the trusted public signing key and its fingerprint
``railval audit rotate-key [--reason TEXT]``  a new signing key, handed over in a signed row
``railval audit seal [--reason TEXT]``  sign the current head (rows written before signing)
``railval audit export DIR``  the offline bundle
``railval audit log [--object PREFIX] [--actor NAME] [--json]``  the trail, oldest first
``railval audit report --out FILE.html|FILE.pdf``  the assessor's audit report

``railval signoff create CAMPAIGN --config NAME --decision validated|restricted|not-validated
[--restrictions TEXT] --statement TEXT [--justification TEXT] [--password-stdin | --password-file F]``
    sign as ``--as USER``: prints what is signed (verdict, 12 quantities, coverage, marks,
    diagnosis, workshops, earlier sign-offs), then asks the password again; a decision
    contrary to the objective verdict needs ``--justification`` (else exit 2, nothing asked)
``railval signoff summary CAMPAIGN --config NAME [--json]``  what a sign-off would bind
``railval signoff list [CAMPAIGN] [--config NAME] [--json]`` / ``railval signoff show ID``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from railval.app.cli import emit_json
from railval.core.errors import RailvalError
from railval.core import lazy

# the services and records this module's verbs call, imported when a verb first uses
# them (railval.core.lazy): `railval --help` and the other verbs never load them
app_audit_report = lazy.module("railval.app.audit_report")
app_cmd_user = lazy.module("railval.app.cli.cmd_user")
audit_service = lazy.module("railval.app.services.audit")
database_service = lazy.module("railval.app.services.database")
signoff_service = lazy.module("railval.app.services.signoff")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("audit", help="audit trail: checkpoint, verify, export, log, report")
    au = p.add_subparsers(dest="subverb", metavar="SUBVERB")
    au.required = True

    c = au.add_parser("checkpoint", help="write the audit head (count + hash) to a file")
    c.add_argument("file", help="checkpoint file to write (keep a copy away from the database)")
    c.set_defaults(func=_cmd_checkpoint)

    v = au.add_parser("verify", help="verify chain, signal hashes and sign-offs; exit 0 if all hold")
    v.add_argument("--checkpoint", metavar="FILE", help="a checkpoint written earlier")
    v.add_argument("--bundle", metavar="DIR", help="verify an exported bundle (no database)")
    v.add_argument("--quick", action="store_true",
                   help="skip decoding the signal blobs and recomputing the validation")
    v.add_argument("--json", action="store_true", help="print the result as JSON")
    v.set_defaults(func=_cmd_verify)

    v.add_argument("--witness", metavar="FILE",
                   help="witness file of signed heads (default: the one beside the signing key)")
    v.add_argument("--no-witness", action="store_true", help="do not compare with a witness file")
    v.add_argument("--public-key", metavar="HEX|FILE",
                   help="trust only this Ed25519 public key (hex, or a file from `audit key "
                   "--json`); default: the key pinned in the server's configuration directory")
    v.add_argument("--trust-fingerprint", metavar="FP", action="append", default=[],
                   help="trust the key with this SHA-256 fingerprint (repeatable); with "
                   "--public-key or alone, nothing is written")

    rk = au.add_parser("rotate-key", help="replace the signing key: a key.rotate row signed "
                       "by the current key and countersigned by the new one")
    rk.add_argument("--reason", default="", help="why (e.g. 'yearly rotation')")
    rk.set_defaults(func=_cmd_rotate_key)

    k = au.add_parser("key", help="print the public signing key and its fingerprint")
    k.add_argument("--json", action="store_true")
    k.set_defaults(func=_cmd_key)

    sl_ = au.add_parser("seal", help="append a signed row that seals the current head")
    sl_.add_argument("--reason", default="", help="why (e.g. 'signing enabled')")
    sl_.set_defaults(func=_cmd_seal)

    e = au.add_parser("export", help="write the offline audit bundle to a new folder")
    e.add_argument("dir")
    e.set_defaults(func=_cmd_export)

    lg = au.add_parser("log", help="print the audit trail")
    lg.add_argument("--object", default=None, help="object prefix, e.g. configuration:demo/")
    lg.add_argument("--actor", default=None)
    lg.add_argument("--json", action="store_true")
    lg.set_defaults(func=_cmd_log)

    r = au.add_parser("report", help="write the assessor's audit report (HTML or PDF)")
    r.add_argument("--out", required=True, help="output file, .html or .pdf")
    r.set_defaults(func=_cmd_report)

    _register_signoff(sub)


def _register_signoff(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("signoff", help="independent sign-off of a configuration")
    so = s.add_subparsers(dest="subverb", metavar="SUBVERB")
    so.required = True
    cr = so.add_parser("create", help="sign off a configuration (asks your password again)")
    cr.add_argument("campaign")
    cr.add_argument("--config", required=True)
    cr.add_argument("--decision", required=True,
                    choices=["validated", "restricted", "not-validated"])
    cr.add_argument("--restrictions", default="", help="required with --decision restricted")
    cr.add_argument("--statement", required=True, help="the reviewer's statement")
    cr.add_argument("--justification", default="",
                    help="written justification; required when the decision is contrary to "
                    "the objective verdict (validated while NOT VALIDATED, not validated while "
                    "VALIDATED, validated on an in-sample verdict)")
    g = cr.add_mutually_exclusive_group()
    g.add_argument("--password-stdin", action="store_true")
    g.add_argument("--password-file", metavar="FILE")
    cr.add_argument("--json", action="store_true")
    cr.set_defaults(func=_cmd_signoff_create)
    sm = so.add_parser("summary", help="what a sign-off of the configuration would bind "
                       "(verdict, quantities, coverage, diagnosis, workshops, sign-offs)")
    sm.add_argument("campaign")
    sm.add_argument("--config", required=True)
    sm.add_argument("--json", action="store_true")
    sm.set_defaults(func=_cmd_signoff_summary)
    sl = so.add_parser("list", help="list sign-offs with their status (valid / stale)")
    sl.add_argument("campaign", nargs="?")
    sl.add_argument("--config", default=None)
    sl.add_argument("--json", action="store_true")
    sl.set_defaults(func=_cmd_signoff_list)
    sh = so.add_parser("show", help="show one sign-off with its evidence and status")
    sh.add_argument("id", type=int)
    sh.add_argument("--json", action="store_true")
    sh.set_defaults(func=_cmd_signoff_show)


def _database(args):
    return database_service.open_database(args.db)


def _cmd_checkpoint(args) -> int:
    doc = audit_service.write_checkpoint(_database(args), args.file)
    print(f"checkpoint written to {args.file}: {doc['seq']} rows, head {doc['row_hash']}")
    return 0


def _cmd_verify(args) -> int:
    checkpoint = audit_service.read_checkpoint(args.checkpoint) if args.checkpoint else None
    if args.bundle:
        report = audit_service.verify_bundle(args.bundle, checkpoint, public_key=args.public_key,
                                   trust_fingerprints=args.trust_fingerprint)
    else:
        report = audit_service.verify_database(_database(args), checkpoint, signals=not args.quick,
                                     full=not args.quick, witness=args.witness,
                                     use_witness=not args.no_witness,
                                     public_key=args.public_key,
                                     trust_fingerprints=args.trust_fingerprint)
    if args.json:
        emit_json(report.to_dict())
    else:
        _print_report(report, checkpoint)
    return 0 if report.ok else 1


def _print_report(report, checkpoint) -> None:
    print(f"audit verify {report.source}: {report.rows} audit rows, head seq "
          f"{report.head_seq} {report.head_hash[:16]}…, {report.signals} stored arrays, "
          f"{report.signoffs} sign-offs ({report.seconds:.2f} s)")
    for t in report.trust:
        rows = (f", rows {t['rows_from']}–{t['rows_to']}" if t["rows_to"] is not None
                else (f", rows from {t['rows_from']}" if t["rows_from"] > 1 else ""))
        print(f"  trusted key {t['fingerprint']} ({t['source']}{rows})")
    print(f"  signatures: {report.signed_rows} signed rows"
          + (f"; witness {report.witness}: {report.witness_heads} signed heads"
             if report.witness else "")
          + ("" if report.seals_checked else "; seals: not checked (no secret)"))
    for note in report.notes:
        print(f"  note: {note}")
    if report.ok and not report.rows and not report.signoffs and not report.signals:
        print("OK, nothing to verify: the database holds no audit row, no sign-off and no "
              "stored array")
    elif report.ok:
        print("OK: the chain, the signatures, " + ("the witness, " if report.witness else "")
              + ("the checkpoint, " if checkpoint else "")
              + ("every stored array, " if report.signals else "")
              + "and every sign-off's record and evidence hash hold")
    else:
        print(f"FAILED: first break: {report.findings[0]}")
        for f in report.findings[1:]:
            print(f"  also: {f}")


def _cmd_key(args) -> int:
    info = audit_service.key_info(_database(args))
    if args.json:
        emit_json(info)
        return 0
    print(f"Ed25519 public key  {info['public_key']}")
    print(f"fingerprint SHA-256 {info['fingerprint']}")
    print(f"trusted from        {info['trusted_from']}")
    print(f"key file            {info['key_file']}")
    if info["key_file_fingerprint"] not in (None, info["fingerprint"]):
        print(f"  NOT TRUSTED: the key file holds key {info['key_file_fingerprint']}")
    print(f"trust anchor        {info['anchor_file']}")
    print(f"witness file        {info['witness_file']}")
    for fp in info["retired"]:
        print(f"retired key         {fp}")
    return 0


def _cmd_rotate_key(args) -> int:
    done = audit_service.rotate_key(_database(args), database_service.default_actor(), args.reason)
    print(f"signing key rotated at audit row {done['seq']}: {done['old_fingerprint']} → "
          f"{done['new_fingerprint']}; the new key is pinned; the old private key is at "
          f"{done['old_key_file']} — move it offline")
    return 0


def _cmd_seal(args) -> int:
    seq, h, n = audit_service.seal(_database(args), database_service.default_actor(), args.reason)
    print(f"sealed: signed head seq {seq} {h} (over {n} unsigned earlier rows); "
          "kept in the witness file")
    return 0


def _cmd_export(args) -> int:
    head = audit_service.export_bundle(_database(args), args.dir)
    print(f"audit bundle written to {args.dir}: {head['rows']} rows, head {head['row_hash']}; "
          f"check it with `railval audit verify --bundle {args.dir}`")
    return 0


def _cmd_log(args) -> int:
    rows = audit_service.trail(_database(args), actor=args.actor, object_prefix=args.object)
    if args.json:
        emit_json({"rows": rows})
        return 0
    for r in rows:
        reason = f"  — {r['reason']}" if r["reason"] else ""
        print(f"{r['seq']:>6}  {r['at_utc'][:19]}Z  {r['actor']:<14} {r['action']:<22} "
              f"{r['object']}{reason}")
    return 0


def _cmd_report(args) -> int:
    if Path(args.out).suffix.lower() not in (".html", ".htm", ".pdf"):
        raise RailvalError(f"--out {args.out}: extension must be .html or .pdf")
    rep = app_audit_report.build_audit_report(_database(args))
    path = rep.write(args.out)
    print(f"audit report ({rep.chain_status}) written to {path}")
    return 0


# -- sign-off ----------------------------------------------------------------------------
def _signer(args) -> str:
    who = database_service.default_actor()
    if who.startswith("cli:"):
        raise RailvalError("name the signer with --as USER or RAILVAL_USER")
    return who


def _summary(args) -> dict:
    return signoff_service.summary_of(_database(args), args.campaign, args.config)


def _num(v, fmt: str = "+.3f") -> str:
    return "–" if v is None else format(v, fmt)


def summary_lines(summ: dict) -> list[str]:
    """The summary of what is signed, as plain text lines (``signoff create``/``summary``)."""
    o = summ["objective"]
    marks = []
    if o["in_sample"]:
        marks.append(f"IN-SAMPLE ({o.get('in_sample_note') or 'calibrated'}: sections "
                     f"{', '.join(o['fit_sections'])}; {o.get('held_out_check') or ''})")
    if o["definition_sensitive"]:
        marks.append("DEFINITION-SENSITIVE (another reading of the open definitions flips it)")
    lines = [f"what is signed: {summ['campaign']}/{summ['configuration']}",
             f"  objective verdict  {o['verdict']}" + (f"  [{'; '.join(marks)}]" if marks else ""),
             "  coverage           " + ("complete" if o["coverage"]["ok"] else
                                        "SHORT: " + "; ".join(o["coverage"]["shortfalls"])),
             f"  {'quantity':<9} {'n':>4} {'mean/limit':>10} {'std/limit':>10}  verdict "
             f"(std with n-{o['std_ddof']})"]
    for q in summ["quantities"]:
        flag = "pass" if q["pass"] else "FAIL"
        if q.get("definition_sensitive"):
            flag += " (definition-sensitive)"
        lines.append(f"  {q['quantity']:<9} {q['n']:>4} {_num(q['mean_norm']):>10} "
                     f"{_num(q['std_norm'], '.3f'):>10}  {flag}")
    if summ["supplementary"]:
        lines.append("  supplementary (no limits, not in the verdict): " + ", ".join(
            f"{q['quantity']} mean {_num(q['mean'], '.3g')} {q['unit']}"
            for q in summ["supplementary"]))
    dg = summ["diagnosis"]
    lines.append("  newest diagnosis   " + ("none run" if dg is None else
                 f"run {dg['run']} at {dg['created_at']}: {dg['verdict'] or '?'}, top "
                 f"{dg['top'] or '–'} ({_num(dg['explained'], '.2f')} explained)"
                 + ("" if dg.get("current", True) else " — data changed since")))
    for w in summ["workshops"]:
        share = "–" if w["yes_share"] is None else f"{w['yes_share']:.0%}"
        lines.append(f"  workshop {w['workshop']} ({w['status']}): {w['plots']} plots, "
                     f"{w['answers']} answers, {share} yes")
    if not summ["workshops"]:
        lines.append("  workshops          none on this configuration")
    for so in summ["signoffs"]:
        lines.append(f"  earlier sign-off {so['id']} [{so['status'].upper()}] "
                     f"{so['decision_text']} by {so['printed_name']} at {so['signed_at_utc'][:19]}Z"
                     + ("  CONTRARY TO OBJECTIVE VERDICT" if so["contrary_to_objective"] else ""))
    lines.append("  evidence pages     " + "  ".join(summ["links"].values()))
    return lines


def _cmd_signoff_summary(args) -> int:
    summ = _summary(args)
    if args.json:
        emit_json(summ)
    else:
        print("\n".join(summary_lines(summ)))
    return 0


def _cmd_signoff_create(args) -> int:
    database = _database(args)
    username = _signer(args)
    summ = _summary(args)
    # read before the password is asked; with --json on stderr (stdout holds one document,
    # which carries the summary as "summary")
    print("\n".join(summary_lines(summ)), file=sys.stderr if args.json else sys.stdout,
          flush=True)
    contrary = summ["contrary_if"][args.decision]
    if contrary and not args.justification.strip():
        raise RailvalError(f"{contrary}: a decision contrary to the objective verdict needs "
                           "--justification TEXT; nothing was signed")
    password = app_cmd_user.read_password(args, confirm=False, prompt=f"Password of {username} (signature): ")
    rec = signoff_service.sign(database, username, password, args.campaign, args.config,
                               decision=args.decision, restrictions=args.restrictions,
                               statement=args.statement, justification=args.justification, source="cli")
    if args.json:
        rec = {k: v for k, v in rec.items() if k != "manifest"}
        emit_json({**rec, "summary": summ})
    else:
        _print_signoff(rec, "valid", [])
    return 0


def _print_signoff(rec: dict, status: str, reasons: list[str]) -> None:
    contrary = "  CONTRARY TO OBJECTIVE VERDICT" if rec.get("contrary_to_objective") else ""
    print(f"sign-off {rec['id']}: {rec['campaign']}/{rec['configuration']} — "
          f"{rec['decision_text'].upper()}  [{status.upper()}]{contrary}")
    print(f"  signed by   {rec['printed_name']} ({rec['username']})")
    print(f"  at          {rec['signed_at_utc']} (UTC)")
    print(f"  meaning     {rec['meaning']}")
    print(f"  objective   {rec.get('objective_verdict') or '–'}")
    if rec["restrictions"]:
        print(f"  restrictions {rec['restrictions']}")
    print(f"  statement   {rec['statement']}")
    if rec.get("justification"):
        print(f"  justification {rec['justification']}")
    print(f"  evidence    SHA-256 {rec['evidence_sha256']} (railval {rec['software_version']})")
    for r in reasons:
        print(f"  stale: {r}")


def _cmd_signoff_list(args) -> int:
    items = signoff_service.records(_database(args), args.campaign, args.config)
    if args.json:
        emit_json({"signoffs": [{**{k: v for k, v in d.items() if k != "manifest"},
                                 "status": st.status, "stale_reasons": st.reasons}
                                for d, st in items]})
        return 0
    if not items:
        print("no sign-offs")
    for d, st in items:
        print(f"{d['id']:>4}  {st.status.upper():<5}  {d['campaign']}/{d['configuration']}  "
              f"{d['decision_text']}  by {d['printed_name']} at {d['signed_at_utc'][:19]}Z  "
              f"evidence {d['evidence_sha256'][:16]}…"
              + ("  CONTRARY TO OBJECTIVE VERDICT" if d["contrary_to_objective"] else ""))
    return 0


def _cmd_signoff_show(args) -> int:
    rec, st = signoff_service.record(_database(args), args.id)
    if args.json:
        emit_json({**rec, "status": st.status, "stale_reasons": st.reasons})
    else:
        _print_signoff(rec, st.status, st.reasons)
    sys.stdout.flush()
    return 0
