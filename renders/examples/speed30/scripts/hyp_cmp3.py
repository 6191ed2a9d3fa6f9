import sys, numpy as np, time, pickle, importlib.util
# run with PYTHONPATH set to the tree under test
import lipgen.recon.pointreg as new
spec = importlib.util.spec_from_file_location("oldpr", "/tmp/oldpr.py"); old = importlib.util.module_from_spec(spec); spec.loader.exec_module(old)
print(new.__file__)
for f in sys.argv[1:]:
    calls = pickle.load(open(f, "rb"))
    t_old = t_new = 0; same = 0
    for dots, expected, gate in calls:
        c = time.process_time(); a = old._hypotheses(dots, expected, gate); t_old += time.process_time() - c
        c = time.process_time(); b = new._hypotheses(dots, expected, gate); t_new += time.process_time() - c
        same += np.array_equal(a, b)
    print(f, "identical", same, "of", len(calls), "old s", round(t_old, 2), "new s", round(t_new, 2))
