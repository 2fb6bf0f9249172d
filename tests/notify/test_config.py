"""The [notify] section: defaults, a round trip through TOML, errors that name the key, and the
mail password that never is in the file."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from flows.common.config import load_plant_config
from schemas.errors import ConfigError
from schemas.plant_config import MailSpec, NotifySpec, parse_plant_config, plant_config_to_dict

EXAMPLE = Path(__file__).resolve().parents[1] / "fixtures" / "plant_example.toml"
WEBHOOK = {"webhook_url": "https://chat.plant.example/hooks/abc"}
MAIL = {"host": "smtp.plant.example", "from": "valvemon@plant.example", "to": ["a@plant.example", "b@plant.example"],
        "password_env": "VALVEMON_SMTP_PASSWORD"}  # fmt: skip


@pytest.fixture
def raw() -> dict:
    return tomllib.loads(EXAMPLE.read_text())


def test_absent_is_off_and_defaults(raw):
    assert parse_plant_config(raw).notify is None
    raw["notify"] = dict(WEBHOOK)
    n = parse_plant_config(raw).notify
    assert n == NotifySpec(webhook_url=WEBHOOK["webhook_url"])
    assert (n.faulty, n.worn, n.recovered, n.remaining_below_h, n.no_change, n.retries) == (True, True, True, None, False, 3)
    raw["notify"] = {"mail": {"host": "smtp", "from": "v@p.example", "to": "a@p.example", "starttls": False}}
    m = parse_plant_config(raw).notify.mail
    assert m == MailSpec(host="smtp", sender="v@p.example", to=("a@p.example",), port=25, starttls=False)


def test_round_trip_through_toml(raw, tmp_path):
    import tomli_w

    raw["notify"] = WEBHOOK | {"worn": False, "remaining_below_h": 500, "no_change": True, "retries": 5, "mail": MAIL | {"port": 465, "user": "svc"}}
    config = parse_plant_config(raw)
    path = tmp_path / "plant.toml"
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(config)).encode())
    assert load_plant_config(path) == config
    written = tomllib.loads(path.read_text())["notify"]
    assert written["mail"]["password_env"] == "VALVEMON_SMTP_PASSWORD" and written["remaining_below_h"] == 500


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({}, "notify: name a webhook_url or a [notify.mail] table"),
        ({"webhook_url": "chat.plant.example/hook"}, "notify.webhook_url: 'chat.plant.example/hook' is not an http:// or https:// URL"),
        (WEBHOOK | {"faulty": "yes"}, "notify.faulty: expected true or false"),
        (WEBHOOK | {"remaining_below_h": 0}, "notify.remaining_below_h: 0 must be > 0"),
        (WEBHOOK | {"retries": 0}, "notify.retries: expected a whole number of attempts 1-10"),
        (WEBHOOK | {"channel": "teams"}, "notify.channel: unknown key"),
        ({"mail": MAIL | {"password": "hunter2"}}, "notify.mail.password: a password is never kept in the file"),
        ({"mail": {k: v for k, v in MAIL.items() if k != "to"}}, "notify.mail.to: missing required key"),
        ({"mail": MAIL | {"to": ["ops"]}}, "notify.mail.to[0]: 'ops' is not a mail address"),
        ({"mail": MAIL | {"port": 70000}}, "notify.mail.port: expected a port number 1-65535"),
        ({"mail": MAIL | {"password_env": "MY PASSWORD"}}, "notify.mail.password_env: 'MY PASSWORD' is not an environment variable name"),
        ("https://x", "notify: expected a table"),
    ],
)
def test_broken_notify_names_the_key(raw, table, message):
    raw["notify"] = table
    with pytest.raises(ConfigError, match=None) as err:
        parse_plant_config(raw)
    assert str(err.value).startswith(message)
