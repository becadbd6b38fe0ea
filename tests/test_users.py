"""Users, roles, invitations and sign-in on SQLite and PostgreSQL (db/users.py)."""

from __future__ import annotations

import datetime as dt

import pytest
from argon2 import PasswordHasher

from railval.core.errors import InvalidParameter, NotFound
from railval.core.roles import ROLES, PermissionDenied, Principal, allowed, require
from railval.db import audit, users
from railval.db.models import AppUser, Invitation


def _rows(database, **filters):
    with database.session() as s:
        return list(audit.iter_rows(s, **filters))


def test_create_user_stores_an_argon2id_hash_never_the_password(database):
    with database.session(write=True) as s:
        users.create_user(s, "ada", display_name="Ada Lovelace", password="correct horse",
                          roles=["engineer", "reviewer"], actor="admin0")
    with database.session() as s:
        u = users.get_user(s, "ada")
        assert u.password_hash.startswith("$argon2id$")
        assert "correct horse" not in u.password_hash
        assert PasswordHasher().verify(u.password_hash, "correct horse")
        assert u.role_names == ["engineer", "reviewer"]
        assert users.verify_password(s, "ada", "correct horse").username == "ada"
        assert users.verify_password(s, "ada", "wrong horse!") is None
        assert users.verify_password(s, "nobody", "correct horse") is None
    (row,) = _rows(database, action="user.add")
    assert (row["actor"], row["object"], row["before_sha256"]) == ("admin0", "user:ada", None)
    assert len(row["after_sha256"]) == 64


def test_bad_user_input_is_refused_with_the_field_named(database):
    with database.session(write=True) as s:
        with pytest.raises(InvalidParameter, match="password: at least 8"):
            users.create_user(s, "bob", password="short")
        with pytest.raises(InvalidParameter, match="user name '<script>'"):
            users.create_user(s, "<script>", password="long enough")
        with pytest.raises(Exception, match="unknown role.*'king'"):
            users.create_user(s, "bob", password="long enough", roles=["king"])
    with database.session(write=True) as s:
        users.create_user(s, "bob", password="long enough")
        with pytest.raises(InvalidParameter, match="already exists"):
            users.create_user(s, "bob", password="long enough")
    with database.session() as s:
        assert [u.username for u in users.list_users(s)] == ["bob"]
        with pytest.raises(NotFound, match="'carol'"):
            users.get_user(s, "carol")


def test_roles_disable_and_password_change_are_audited(database):
    with database.session(write=True) as s:
        users.create_user(s, "eve", password="password-1", roles=["reviewer"])
    with database.session(write=True) as s:
        users.set_roles(s, "eve", ["assessor", "reviewer"], actor="root", reason="audit 2026")
        users.set_password(s, "eve", "password-2", actor="root")
    with database.session(write=True) as s:
        assert users.verify_password(s, "eve", "password-1") is None
        assert users.verify_password(s, "eve", "password-2") is not None
        users.disable(s, "eve", actor="root", reason="left the project")
    with database.session() as s:
        assert users.verify_password(s, "eve", "password-2") is None
        assert users.principal(users.get_user(s, "eve")).roles == frozenset()
    actions = [r["action"] for r in _rows(database, object="user:eve")]
    assert actions == ["user.add", "user.roles", "user.password", "user.disable"]
    roles_row = _rows(database, action="user.roles")[0]
    assert roles_row["reason"] == "audit 2026" and roles_row["before_sha256"] != roles_row["after_sha256"]


def test_authenticate_records_failures_and_rate_limits(database):
    with database.session(write=True) as s:
        users.create_user(s, "ann", password="right password", roles=["engineer"])
        users.create_user(s, "gone", password="right password", roles=["engineer"])
        users.disable(s, "gone")
    with database.session(write=True) as s:
        assert users.authenticate(s, "ann", "right password", source="10.0.0.1").ok
    with database.session(write=True) as s:
        r = users.authenticate(s, "gone", "right password", source="10.0.0.1")
        assert not r.ok and "disabled" in r.message
    with database.session(write=True) as s:
        r = users.authenticate(s, "gone", "wrong password", source="10.0.0.1")
        assert r.message == "Wrong user name or password."
    for _ in range(users.MAX_FAILURES_PER_USER):
        with database.session(write=True) as s:
            r = users.authenticate(s, "ann", "wrong password", source="10.0.0.2")
            assert r.message == "Wrong user name or password."
    with database.session(write=True) as s:  # the right password no longer helps within the window
        r = users.authenticate(s, "ann", "right password", source="10.0.0.2")
        assert not r.ok and "Too many failed sign-ins" in r.message
    failed = _rows(database, action="login.failed")
    assert len(failed) == 2 + users.MAX_FAILURES_PER_USER
    assert {r["detail"]["source"] for r in failed} == {"10.0.0.1", "10.0.0.2"}
    assert [r["object"] for r in _rows(database, action="login.refused")] == ["user:ann"]


def test_invitation_is_single_use_hashed_and_expires(database):
    with database.session(write=True) as s:
        users.create_user(s, "org", password="organiser pw", roles=["organiser"])
    with pytest.raises(NotFound, match="workshop '7' not found"):  # it must exist
        with database.session(write=True) as s:
            users.create_invitation(s, workshop_ref=7, actor="org")
    with database.session(write=True) as s:
        inv, token = users.create_invitation(s, actor="org")
        old, old_token = users.create_invitation(s, valid_for=dt.timedelta(seconds=1), actor="org")
    with database.session() as s:
        stored = s.get(Invitation, inv.id)
        assert token not in (stored.token_sha256, stored.note)
        assert stored.token_sha256 == users.token_hash(token) and stored.workshop_ref is None
    with database.session(write=True) as s:
        user = users.redeem_invitation(s, token, username="rev1", password="reviewer pw",
                                       display_name="Reviewer One")
        assert user.role_names == ["panelist"]
    with database.session(write=True) as s:
        with pytest.raises(users.InvitationRefused, match="already been used"):
            users.redeem_invitation(s, token, username="rev2", password="reviewer pw")
        with pytest.raises(users.InvitationRefused, match="not valid"):
            users.check_invitation(s, token + "x")
    with database.session(write=True) as s:  # make the second invitation expired without waiting
        s.query(Invitation).filter_by(id=old.id).update(
            {"expires_at": dt.datetime.now(dt.UTC) - dt.timedelta(minutes=1)})
    with database.session(write=True) as s:
        with pytest.raises(users.InvitationRefused, match="expired"):
            users.redeem_invitation(s, old_token, username="rev3", password="reviewer pw")
    with database.session(write=True) as s:
        assert s.query(AppUser).filter(AppUser.username.in_(["rev2", "rev3"])).count() == 0
        users.record_refusal(s, old_token, "expired", source="127.0.0.1")
    assert [r["action"] for r in _rows(database, object_prefix="invitation:")] == [
        "invitation.create", "invitation.create", "invitation.redeem", "invitation.refused"]


def test_role_registry_is_the_one_list():
    assert list(ROLES) == ["admin", "organiser", "engineer", "panelist", "reviewer", "assessor"]
    assessor = Principal("a", frozenset({"assessor"}))
    assert allowed(assessor, "audit.read") and not allowed(assessor, "calibrate")
    with pytest.raises(PermissionDenied, match="a \\(assessor\\) may not calibrate.*engineer"):
        require(assessor, "calibrate")
    with pytest.raises(KeyError):
        allowed(assessor, "no.such.action")
