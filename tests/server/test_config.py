"""The cell file as server/config.py composes it: the `host` section's keys come from the
packages that own them, each section's rules are reported at their key path, and a machine
process reading a cell file leaves the host section to the host."""

from __future__ import annotations

import hashlib
import textwrap

import pytest

from cnc.config import ConfigError, load_machine_config
from dnc.config import DncConfig
from server.config import HostConfig, MqttConfig, load_cell_config
from web_api.config import ApiConfig

ONE = {"m1": {"base": "mill3"}}


def test_the_host_section_is_the_union_of_its_owners_keys():
    owned = {*DncConfig.model_fields, *ApiConfig.model_fields}
    assert set(HostConfig.model_fields) == owned | {"faults", "mqtt", "mtconnect_buffer_size"}
    assert set(DncConfig.model_fields) == {"database_url", "lost_contact_s", "dispatch_rule"}
    assert set(ApiConfig.model_fields) == {"bind", "port", "auth", "tls"}
    assert HostConfig.model_fields["mqtt"].annotation == MqttConfig | None


def problems_of(tmp_path, host_yaml: str) -> list[str]:
    path = tmp_path / "cell.yaml"
    text = "machines:\n  m1: {base: mill3}\nhost:\n" + textwrap.indent(host_yaml, "  ")
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_cell_config(path)
    prefix = f"{path}:"
    lines = str(info.value).splitlines()
    assert all(line.startswith(prefix) for line in lines), lines
    return [line[len(prefix) :] for line in lines]


def test_each_owners_rules_are_reported_at_the_key_with_file_and_line(tmp_path):
    host = (
        "dispatch_rule: lifo\n"
        "auth:\n"
        "  api_keys:\n"
        "    - {user: a, role: admin, key: aaaaaaaaaaaaaaaa}\n"
        "    - {user: b, role: viewer, key: aaaaaaaaaaaaaaaa}\n"
        "    - {user: c, role: viewer}\n"
    )
    assert problems_of(tmp_path, host) == [
        "8:9: host.auth.api_keys.1: the same key as api_keys[0]",
        "9:9: host.auth.api_keys.2: api key of 'c': give exactly one of key, key_sha256",
        "4:18: host.dispatch_rule: unknown dispatch rule 'lifo'; known rules: fifo, spt, edd,"
        " cr, same_program_first (a setup-aware one may fall back to another:"
        " 'same_program_first then edd')",
    ]


@pytest.mark.parametrize(
    ("host", "expected"),
    [
        ("auth: {api_keys: [{user: a, role: boss, key: aaaaaaaaaaaaaaaa}]}\n",
         "4:37: host.auth.api_keys.0.role: must be one of 'viewer', 'operator', 'programmer'"),
        ("auth: {failures_max: 0}\n", "4:24: host.auth.failures_max: must be >= 1, got 0"),
        ("auth: {failures_window_s: 7200}\n",
         "4:29: host.auth.failures_window_s: must be <= 3600, got 7200"),
        ("auth: {failure_max: 3}\n",
         "4:23: host.auth.failure_max: unknown key (did you mean 'failures_max'?"),
        ("tls: {cert: a.pem}\n", "4:3: host.tls.key: required key missing"),
        ("lost_contact_s: 0\n", "4:19: host.lost_contact_s: must be > 0, got 0"),
    ],
)  # fmt: skip
def test_host_key_errors(tmp_path, host, expected):
    assert any(line.startswith(expected) for line in problems_of(tmp_path, host))


def test_the_auth_section_gives_the_apps_settings():
    cell = load_cell_config(
        {
            "machines": ONE,
            "host": {
                "auth": {
                    "api_keys": [{"user": "op", "role": "operator", "key": "k" * 16}],
                    "failures_max": 3,
                    "failures_window_s": 60.0,
                }
            },
        }
    )
    settings = cell.host.auth.api_settings()
    assert (settings.auth_failures_max, settings.auth_failures_window_s) == (3, 60.0)
    principal = settings.authenticate("k" * 16)
    assert principal is not None and (principal.user, principal.role.name) == ("op", "operator")
    assert settings.authenticate("x" * 16) is None
    # the defaults are the app's own
    default = load_cell_config({"machines": ONE}).host.auth.api_settings()
    assert default.auth_failures_max == 10 and default.api_keys == ()


def test_an_api_key_is_one_model_in_the_cell_file_and_the_apps_settings():
    """web_api.settings.ApiKey is declared once: the cell file's `host.auth.api_keys[]`
    entries are ApiKeys, handed to the app's settings as they are, and the same entries
    given to ApiSettings directly make equal keys."""
    from web_api.config import AuthConfig
    from web_api.settings import ApiKey, ApiSettings, Role

    digest = hashlib.sha256(b"c" * 20).hexdigest()
    entries = [
        {"user": "op", "role": "operator", "key": "k" * 16},
        {"user": "ci", "role": "viewer", "key_sha256": digest},
    ]
    cell = load_cell_config({"machines": ONE, "host": {"auth": {"api_keys": entries}}})
    keys = cell.host.auth.api_keys
    assert [type(k) for k in keys] == [ApiKey, ApiKey]
    assert AuthConfig.model_fields["api_keys"].annotation == list[ApiKey]
    settings = cell.host.auth.api_settings()
    assert settings.api_keys == tuple(keys)
    assert ApiSettings.from_mapping({"api_keys": entries}).api_keys == settings.api_keys
    assert settings.authenticate("c" * 20).role is Role.viewer
    assert ApiKey(user="x", role=Role.admin, key="k" * 16).role is Role.admin
    assert [k.role for k in keys] == [Role.operator, Role.viewer]


def test_a_machine_reads_its_section_of_a_cell_file_without_the_hosts(tmp_path):
    """`fmscell machine --config cell.yaml` needs its machine; the host validates `host`."""
    path = tmp_path / "cell.yaml"
    path.write_text("machines:\n  m1: {base: mill3}\nhost: {dispatch_rule: lifo}\n")
    assert load_machine_config(path, "m1").kind == "mill"
    with pytest.raises(ConfigError, match="host.dispatch_rule"):
        load_cell_config(path)
