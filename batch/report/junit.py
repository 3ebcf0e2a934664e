"""--junit FILE: a run's jobs as JUnit XML, the test-report format CI systems display (GitHub
Actions test reporters, GitLab, Jenkins, Azure). Layout after the Ant JUnit task's format as CI
systems read it (testsuites > testsuite > testcase; failure and skipped carry a message):

  one <testcase> per run entry: classname = scene, name = backend/mode, time = render seconds
  failed                  -> <failure message=reason type="failed">
  skipped, unsupported    -> <skipped message="skipped: reason">, <skipped message="unsupported: reason">
  unjudged                -> <skipped message="unjudged: reason">: a CI does not go red on a render
                             that nothing could judge, and shows it as not passed (the runner's
                             exit status 3 still says it)
  known, fixed, ok        -> passed; known and fixed name their deviation ids in the test case's
                             <properties> (property "known" / "fixed")

Every test case also has properties "status", "judged by" (the probes measured and who made the
reference; "checked against itself: detects change, not error" where a renderer's own reference was
its only judge: batch/report/results.py) and, where the run has them, "baseline" (the --baseline
verdict), "noise test" (batch/records.py noise_test_text) and "diagnosis" (the fitted error models'
verdict, issue 34: a failure's message, its reason, carries it too), "worst bands" (a spectral
render's failing probe regions, each by its worst band, issue 33: batch/report/spectra.py), and its reason, noise test,
judged by and diagnosis in <system-out>. Written with xml.etree (attribute and text escaping is the library's);
characters XML 1.0 cannot carry (control characters, lone surrogates) are replaced first, since
reasons quote files and renderers' output.
"""
import re
import socket
from pathlib import Path
from xml.etree import ElementTree as ET

from ..records import flip_text, noise_test_text
from .results import judged_by
from .spectra import worst_lines

# status -> (element under the test case or None for a pass, its message prefix)
OUTCOME = {"failed": ("failure", ""), "skipped": ("skipped", "skipped: "), "unsupported": ("skipped", "unsupported: "),
           "unjudged": ("skipped", "unjudged: "), "known": (None, ""), "fixed": (None, ""), "ok": (None, "")}
UNKNOWN_STATUS = ("failure", "unknown status: ")  # a status this code does not know is not a pass
# XML 1.0 Char production (https://www.w3.org/TR/xml/#charsets): everything else is replaced
_NOT_XML = re.compile("[^\t\n\r\u0020-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def _text(value):
    """Any value as text XML 1.0 can hold (what it cannot is replaced by U+FFFD)."""
    return _NOT_XML.sub("\ufffd", "" if value is None else str(value))


def _seconds(value):
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and value == value and value >= 0
    return f"{value:.3f}" if ok and value != float("inf") else "0.000"


def _property(parent, name, value):
    ET.SubElement(parent, "property", name=_text(name), value=_text(value))


def testcase(run):
    """The <testcase> element of one run entry (a metrics.json runs[] item)."""
    status = run.get("status")
    mode = run.get("mode")
    case = ET.Element("testcase", classname=_text(run.get("scene")),
                      name=_text(f"{run.get('backend')}/{mode}" if mode else run.get("backend")),
                      time=_seconds(run.get("time_s")))
    props = ET.SubElement(case, "properties")
    _property(props, "status", status)
    if judged_by(run):
        _property(props, "judged by", judged_by(run))
    for key in ("known", "fixed"):
        ids = run.get(key)
        if isinstance(ids, list) and ids:
            _property(props, key, ", ".join(map(str, ids)))
    test = noise_test_text(run.get("test"))
    if test:
        _property(props, "noise test", test)
    if flip_text(run):
        _property(props, "FLIP", flip_text(run))
    diagnosis = run.get("diagnosis")
    why = diagnosis.get("text") if isinstance(diagnosis, dict) else None
    if why:
        _property(props, "diagnosis", why)
    worst = worst_lines(run)
    if worst:
        _property(props, "worst bands", "; ".join(worst))
    baseline = run.get("baseline")
    if isinstance(baseline, dict) and baseline.get("status"):
        _property(props, "baseline", baseline["status"])
    element, prefix = OUTCOME.get(status, UNKNOWN_STATUS) if isinstance(status, str) else UNKNOWN_STATUS
    reason = _text(run.get("reason"))
    if element == "failure":
        ET.SubElement(case, "failure", message=prefix + reason, type=_text(status)).text = reason
    elif element == "skipped":
        ET.SubElement(case, "skipped", message=prefix + reason)
    out = [f"status: {_text(status)}"] + ([f"reason: {reason}"] if reason else []) + \
          ([f"noise test: {_text(test)}"] if test else []) + ([f"judged by: {_text(judged_by(run))}"] if judged_by(run) else []) + \
          ([f"diagnosis: {_text(why)}"] if why else [])
    ET.SubElement(case, "system-out").text = "\n".join(out)
    return case


def document(runs, name="spectral_bench", started=None, properties=None):
    """<testsuites> holding one <testsuite> ``name`` with a test case per run entry."""
    runs = [r for r in runs if isinstance(r, dict)]
    cases = [testcase(r) for r in runs]
    failures = sum(c.find("failure") is not None for c in cases)
    skipped = sum(c.find("skipped") is not None for c in cases)
    total = sum(float(c.get("time")) for c in cases)
    root = ET.Element("testsuites", name="spectral_bench", tests=str(len(cases)), failures=str(failures),
                      errors="0", skipped=str(skipped), time=f"{total:.3f}")
    suite = ET.SubElement(root, "testsuite", name=_text(name), tests=str(len(cases)), failures=str(failures),
                          errors="0", skipped=str(skipped), time=f"{total:.3f}", hostname=_text(socket.gethostname()))
    if started:
        suite.set("timestamp", _text(started))
    props = ET.SubElement(suite, "properties")
    for key, value in (properties or {}).items():
        _property(props, key, value)
    suite.extend(cases)
    return ET.ElementTree(root)


def write(path, runs, name="spectral_bench", started=None, properties=None):
    """Write the JUnit XML of ``runs`` to ``path`` (atomically: a CI never reads half a file)."""
    path = Path(path)
    tree = document(runs, name, started, properties)
    ET.indent(tree)
    tmp = path.with_name(path.name + ".tmp")
    tree.write(tmp, encoding="utf-8", xml_declaration=True)
    tmp.replace(path)
    return path
