# A walk of E moves (stdin, JSON: [weights, signed moves]) through the mixer: true if
# every drive is back where it was at each E position it returns to, and each reverse
# step undoes the last forward step's drive.
import json
import sys

from mixer_picks import picks

weights, moves = json.loads(sys.stdin.read())
seq = picks(weights, moves)
pos = [0] * len(weights)
at = {0: list(pos)}
e = 0
history = []
ok = len(seq) == sum(abs(m) for m in moves)
k = 0
for m in moves:
    for _ in range(abs(m)):
        d = seq[k]
        k += 1
        if m > 0:
            pos[d] += 1
            e += 1
            history.append(d)
        else:
            pos[d] -= 1
            e -= 1
            if history:
                ok = ok and history.pop() == d
        if e in at:
            ok = ok and at[e] == pos
        else:
            at[e] = list(pos)
print(json.dumps(ok))
