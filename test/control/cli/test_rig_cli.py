"""``pneu rig`` on the simulated card: the driver loop with hosted controllers, no ROS.

Real time on the twin's 1 kHz card clock (0.3 s): the assertions are on counts
and files, never on timing.
"""

import json

import pytest
from pneu_control.cli.main import main
from pneu_control.cli.rig import parse_hold
from pneu_msgs_py.bag.reader import read_run
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.paths import config_file
from pneu_sim.daq_sim.card import read_card_state


def test_rig_on_the_simulated_card_writes_a_bag_and_leaves_the_valves_safe(tmp_path, capsys):
    card = tmp_path / "card"
    rc = main(
        [
            "rig",
            "--backend",
            f"sim:seed=1,card={card}",
            "--axis",
            "linear",
            "--controllers",
            str(config_file("controllers_retuned.yaml")),
            "--hold",
            "rotary=6",
            "--duration",
            "0.3",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    assert rc == 0
    out = capsys.readouterr().out
    assert "cycles 300" in out and "heartbeats" in out
    loop = json.loads((tmp_path / "out" / "loop.json").read_text())["loop"]
    assert loop["cycles"] == "300" and loop["pacing"] == "hardware"
    # the bag: one sample per cycle that had one (a late cycle has none), the linear
    # controller's command for each, the loop's statistics on /diagnostics
    run = read_run(tmp_path / "out" / "run.mcap")
    n = len(run["/pneu/linear/joint_state"])
    codes = dict(c.split(":") for c in loop["daq_late_codes"].split())
    late_reads = sum(int(v) for c, v in codes.items() if c != "-209801")
    assert n == 300 - late_reads
    assert len(run["/pneu/linear/valve_command"]) == n
    assert len(run["/diagnostics"]) >= 1
    st = read_card_state(card)
    assert (st.ao0_v, st.ao1_v, st.do_level) == (5.0, 5.0, False)
    assert st.do_edges >= 1 and st.tick >= 300


def test_hold_values_are_checked():
    assert parse_hold("linear=5.05,rotary=5") == {"linear": 5.05, "rotary": 5.0}
    with pytest.raises(ParamError, match=r"--hold linear: 11 refused; allowed: \[0, 10\] V"):
        parse_hold("linear=11")
    with pytest.raises(ParamError, match=r"--hold: 'x' refused; allowed: one of linear, rotary"):
        parse_hold("x=5")
