"""A FlowTest test artifact, run without FlowTest: the reference reader.

Plain Python with no import but ``json``, written to be ported line by line (C++, Rust, a
PLC): lists, dicts and integers only. It plays every kind of test (static walls, reactive
doors, mixed, and a test agent with its controller table) exactly as FlowTest's
environments do; FlowTest's test suite holds it to them step by step
(tests/docs/test_reference_reader.py). The fields it reads are explained in
docs/artifact-schema.md.

    test = Test(json.load(open("maze2.json")))
    run = test.reset()
    while run.outcome == "open" and run.steps < 100:
        mask = test.mask(run)              # 1 per allowed action: grid N S E W stay, graph slots + stay
        test.step(run, mask.index(1))      # your system chooses; here the first allowed action
    print(test.verdict(run))
"""

import json

GRID_ACTIONS = ["N", "S", "E", "W"]  # a grid's action slots; the last action is stay


def index(value, size, where):
    """``value`` if it indexes a list of ``size`` entries. Anything else is refused: Python
    would read a negative index from the end of the list (a port in C would read memory)."""
    if type(value) is not int or not 0 <= value < size:
        raise ValueError(f"{where}: {value!r} is not an index in 0..{size - 1}")
    return value


def indices(values, size, where, length=None):
    """Every entry of ``values`` checked by :func:`index` (and, given ``length``, their number)."""
    if length is not None and len(values) != length:
        raise ValueError(f"{where}: {len(values)} entries, expected {length}")
    return [index(v, size, f"{where}[{k}]") for k, v in enumerate(values)]


class Run:
    """One test run: the system's state, the history (a state of automata.histories), the
    test agent's state and memory (-1 without an agent), and the verdict's counters."""

    def __init__(self, system, history):
        self.system, self.history = system, history
        self.agent, self.memory = -1, -1
        self.steps = self.restrictions = self.blocked_attempts = 0
        self.outcome = "open"  # "met" or "violated" once the run has ended


class Test:
    def __init__(self, doc):
        ts = doc["system"]
        n, moves = len(ts["states"]), ts["moves"]
        letter_of = {json.dumps(sorted(a)): i for i, a in enumerate(doc["letters"])}
        self.letter = [letter_of[json.dumps(sorted(lab))] for lab in ts["labels"]]
        hist = doc["automata"]["histories"]
        self.delta, self.h0 = hist["delta"], hist["initial"]
        # every index the runs read is checked once, here (validate against the schema first)
        n_hist = len(self.delta)
        for m, move in enumerate(moves):
            indices(move, n, f"system.moves[{m}]", 2)
        for h, row in enumerate(self.delta):  # one entry per letter
            indices(row, n_hist, f"automata.histories.delta[{h}]", len(doc["letters"]))
        for field in ("labels", "stay", "place"):  # one entry per state
            if len(ts[field]) != n:
                raise ValueError(f"system.{field}: {len(ts[field])} entries, expected {n}")
        if len(hist["accepting"]) != n_hist:
            raise ValueError(f"automata.histories.accepting: {len(hist['accepting'])} rows, expected {n_hist}")
        index(hist["initial"], n_hist, "automata.histories.initial")
        self.sys_accepts = [row[0] == 1 for row in hist["accepting"]]
        self.test_accepts = [row[1] == 1 for row in hist["accepting"]]
        self.initial, self.place = index(ts["initial"], n, "system.initial"), ts["place"]
        # action slots: a grid's N S E W by the move's action name, a graph's moves in order
        grid = ts["kind"] in ("grid", "fuel") and ts.get("layout") is not None
        out = [[] for _ in range(n)]
        for m, (a, _) in enumerate(moves):
            out[a].append(m)
        self.n_slots = 4 if grid else max([1] + [len(o) for o in out])
        self.slot = [[-1] * self.n_slots for _ in range(n)]  # slot -> move, -1: none
        for s in range(n):
            for k, m in enumerate(out[s]):
                self.slot[s][GRID_ACTIONS.index(ts["action"][m]) if grid else k] = m
        self.stay = self.n_slots  # the stay action's index
        self.to = [[moves[m][1] if m >= 0 else s for m in self.slot[s]] for s in range(n)]
        self.can_stay = [x == 1 for x in ts["stay"]]
        # the restrictions the test enforces itself, per history: its static walls, and
        # its reactive restrictions unless a test agent realizes them by standing in the way
        static = set(indices(doc["strategy"]["static_obstacles"], len(moves), "strategy.static_obstacles"))
        reactive = {}
        for q, ms in doc["strategy"]["restrictions"].items():
            reactive[index(int(q), n_hist, "strategy.restrictions")] = set(indices(ms, len(moves), f"strategy.restrictions.{q}"))
        self.agent = doc["kind"] == "agent"
        self.enforced = [static | (set() if self.agent else reactive.get(h, set())) for h in range(len(self.delta))]
        self.doomed = self._doomed(n, moves)
        if self.agent:
            c = doc["agent"]["controller"]
            self.ctl = c
            self.agent_place = c["agent_places"]  # place of each agent state, None on a park
            n_agent = len(self.agent_place)
            self.row_of = {(s, h): i for i, (s, h) in enumerate(c["rows"])}
            t = c["table"]
            index(c["initial_agent"], n_agent, "agent.controller.initial_agent")
            indices(t["next_agent"], n_agent, "agent.controller.table.next_agent")
            if len(c["fallback"]) != n_agent:
                raise ValueError(f"agent.controller.fallback: {len(c['fallback'])} rows, expected {n_agent}")
            n_places = len(c["fallback"][0]) if n_agent else 0
            for a, row in enumerate(c["fallback"]):
                indices(row, n_agent, f"agent.controller.fallback[{a}]", n_places)
            indices(c["sys_place"], n_places, "agent.controller.sys_place", n)
            self.answer = {(t["memory"][i], t["row"][i], t["agent"][i]): (t["next_agent"][i], t["next_memory"][i]) for i in range(len(t["row"]))}

    def _doomed(self, n, moves):
        """doomed[h][s]: no run from state s with history h that respects the enforced
        restrictions can reach a history whose system part accepts (backward search)."""
        into = {}  # (h', s') -> the (h, s) that reach it in one step
        for h in range(len(self.delta)):
            steps = [(a, b) for m, (a, b) in enumerate(moves) if m not in self.enforced[h]]
            steps += [(s, s) for s in range(n) if self.can_stay[s]]
            for a, b in steps:
                into.setdefault((self.delta[h][self.letter[b]], b), []).append((h, a))
        can = {(h, s) for h in range(len(self.delta)) if self.sys_accepts[h] for s in range(n)}
        todo = list(can)
        while todo:
            for node in into.get(todo.pop(), []):
                if node not in can:
                    can.add(node)
                    todo.append(node)
        return [[(h, s) not in can for s in range(n)] for h in range(len(self.delta))]

    # ---- the test agent
    def respond(self, run):
        """The test agent's move after the system entered its state (its controller table,
        else the fallback table)."""
        row = self.row_of.get((run.system, run.history))
        got = self.answer.get((run.memory, row, run.agent)) if row is not None else None
        if got is None:
            got = (self.ctl["fallback"][run.agent][self.ctl["sys_place"][run.system]], run.memory)
        run.agent, run.memory = got

    # ---- what the test allows
    def restricted(self, run):
        """The action slots of the system's state refused now: enforced restrictions, and
        moves into the place where the test agent stands."""
        s, out = run.system, set()
        for k, m in enumerate(self.slot[s]):
            if m >= 0 and m in self.enforced[run.history]:
                out.add(k)
            if m >= 0 and run.agent >= 0 and self.agent_place[run.agent] == self.place[self.to[s][k]]:
                out.add(k)
        return out

    def _exists(self, s):
        return {k for k, m in enumerate(self.slot[s]) if m >= 0} | ({self.stay} if self.can_stay[s] else set())

    def legal(self, run):
        ok = self._exists(run.system) - self.restricted(run)
        return ok if ok else {self.stay}  # with every move refused, stay is offered as a no-op

    def mask(self, run):
        """1 per allowed action (all 0 once the run has ended)."""
        ok = set() if run.outcome != "open" else self.legal(run)
        return [1 if a in ok else 0 for a in range(self.stay + 1)]

    # ---- the run
    def _settle(self, run):
        if self.sys_accepts[run.history]:
            run.outcome = "met"
        elif self.doomed[run.history][run.system]:
            run.outcome = "violated"

    def reset(self):
        run = Run(self.initial, self.delta[self.h0][self.letter[self.initial]])
        if self.agent:
            run.agent, run.memory = self.ctl["initial_agent"], self.ctl["initial_memory"]
            if self.ctl["first"] == "agent":
                self.respond(run)
        self._settle(run)
        return run

    def step(self, run, action):
        """The system takes ``action`` (an index in 0..stay, as the env's action space; any
        other is refused); a refused or impossible one leaves it in place."""
        index(action, self.stay + 1, "action")
        s, refused = run.system, self.restricted(run)
        exists, legal = self._exists(s), self.legal(run)
        if refused & exists:
            run.restrictions += 1  # a decision taken with a move restricted
        invalid = action not in exists and not (action == self.stay and legal == {self.stay})
        if invalid or action in refused:
            run.blocked_attempts += 1
        moved = not invalid and action not in refused and action != self.stay
        run.system = self.to[s][action] if moved else s
        run.history = self.delta[run.history][self.letter[run.system]]
        run.steps += 1
        self._settle(run)
        if self.agent and run.outcome == "open":
            self.respond(run)

    def verdict(self, run):
        return {
            "system_objective": run.outcome,
            "test_objective_realized": self.test_accepts[run.history],
            "restrictions": run.restrictions,
            "blocked_attempts": run.blocked_attempts,
            "steps": run.steps,
        }
