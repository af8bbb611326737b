# Transitions in firmware: a mix or tool change takes effect L0 = L1 + L2/2 of printing
# extrusion before the G-code places it (Ovenbird's model: the nozzle delays a change by
# L1 and blends it over L2), so no post-processor and no wipe tower are needed. Moves
# wait here until L0 of printing extrusion follows them; a change applies to the
# waiting moves within L0 of it, splitting the move that crosses that point exactly.
# Only positive extrusion on moves that also move X, Y or Z counts, as in `advance`.
# A tool pair may have its own L1 and L2 (transition_pairs); other changes use the
# defaults. Extrusion is counted in integer nanometres, as the planner takes it.
from mixfw.filament import nm_from_mm, div_round


def l0_mm(l1_mm, l2_mm):
    """Ovenbird's advance: a change shows half-blended L1 + L2/2 after it is made."""
    return l1_mm + l2_mm / 2


class Transitions:
    def __init__(self, planner, default_l0_mm, pairs, reply):
        """pairs: (from_tool, to_tool, l1_mm, l2_mm) each; (0, 0, ...) slots are empty."""
        self.planner = planner
        self.default_l0_mm = default_l0_mm
        self.pair_l0_mm = {(a, b): l0_mm(l1, l2) for a, b, l1, l2 in pairs if a != b}
        # Moves wait for the longest advance any change may need.
        self.l0_mm = max([default_l0_mm] + list(self.pair_l0_mm.values()))
        self.l0_nm = nm_from_mm(self.l0_mm)
        self.tool = -1
        self.reply = reply
        # Each waiting move: [start_xyz, target_xyz, e_nm, feed_mm_s, dir_masks, mix, replay]
        self.pending = []
        self.pending_printing_nm = 0
        self.mix_id = planner.mix_id
        self.tool_mix = planner.tool_mix
        # Where the queued moves end, as X Y Z steps (cmd_motion compares a line's
        # targets with it): the last waiting move's target, or the planner's own
        # position (a list the planner keeps in place) when none waits. A plain
        # attribute: a property, or __getattr__, makes MicroPython look up every store
        # on the instance in its class first (11 us a store on the chip).
        self.position_steps = planner.position_steps

    def synchronize(self):
        self.planner.synchronize()

    @staticmethod
    def _printing_nm(move):
        return move[2] if move[2] > 0 and move[0] != move[1] else 0

    def add_move(self, target_steps, feed_mm_s, dir_masks=None, e_nm=0, mix=None,
                 replay=False):
        start = self.position_steps[:3]
        target = list(target_steps[:3])
        move = [start, target, e_nm, feed_mm_s, dir_masks,
                mix or (self.mix_id, self.tool_mix), replay]
        self.pending.append(move)
        self.position_steps = target
        self.pending_printing_nm += self._printing_nm(move)
        # A move is released once L0 of printing extrusion follows it.
        while self.pending and (self.pending_printing_nm - self._printing_nm(self.pending[0])
                                >= self.l0_nm):
            self._release()
        return True

    def _release(self):
        move = self.pending.pop(0)
        if not self.pending:  # the queue ends where the planner's does
            self.position_steps = self.planner.position_steps
        self.pending_printing_nm -= self._printing_nm(move)
        p = self.planner
        mix_id, weights = move[5]
        p.set_mix(mix_id, weights)
        p.add_move(move[1] + [0], move[3], dir_masks=move[4], e_nm=move[2], replay=move[6])

    def flush(self):
        while self.pending:
            self._release()

    def drop(self):
        """A halt: waiting moves are dropped with the queue."""
        self.pending = []
        self.pending_printing_nm = 0
        self.position_steps = self.planner.position_steps

    def set_mix(self, mix_id, weights, tool=-1):
        """A mix change: it reaches back over the last L0 of printing extrusion, the
        pair's own if it has one (tool: the virtual tool selected, -1 for a mix change
        within a tool, such as a gradient's)."""
        self.mix_id = mix_id
        self.tool_mix = tuple(weights)
        mix = (mix_id, self.tool_mix)
        l0 = self.pair_l0_mm.get((self.tool, tool), self.default_l0_mm)
        if tool >= 0:
            self.tool = tool
        need = nm_from_mm(l0)
        k = len(self.pending)
        while k > 0 and need > 0:
            move = self.pending[k - 1]
            e = self._printing_nm(move)
            if e > need:
                self._split(k - 1, need)  # the part after the split is pending[k]
                break
            need -= e
            k -= 1
        else:
            if need > 0:
                self.reply("echo:transition advanced %.3f of %.3f mm: too little extrusion "
                           "queued before the change" % (l0 - need / 1e6, l0))
        for move in self.pending[k:]:
            move[5] = mix

    def _split(self, index, tail_nm):
        """Split pending[index] so that its last tail_nm of extrusion is a move of its own."""
        start, target, e, feed, masks, mix, replay = self.pending[index]
        mid = [start[i] + div_round((target[i] - start[i]) * (e - tail_nm), e)
               for i in range(3)]
        self.pending[index] = [start, mid, e - tail_nm, feed, masks, mix, replay]
        self.pending.insert(index + 1, [mid, target, tail_nm, feed, masks, mix, replay])
