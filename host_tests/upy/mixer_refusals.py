# mixer.normalize of an all-zero, a negative and an empty mix: "accepted" or why not.
import json

from mixfw import mixer

res = []
for w in ([0, 0, 0], [1, -1, 0], []):
    try:
        mixer.normalize(w, 3)
        res.append("accepted")
    except mixer.MixError as e:
        res.append(str(e))
print(json.dumps(res))
