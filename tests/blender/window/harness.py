"""Helpers for the window scenarios, imported by driver.py inside Blender (a module of its own:
Blender replaces the __main__ namespace of the --python script when a file is loaded)."""
import json
import os
import sys
import time
import traceback

import bpy

args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
SCENARIO, OUT = args[0], args[1]
os.makedirs(OUT, exist_ok=True)
RESULT = {"scenario": SCENARIO}


def log(message: str) -> None:
    print(f"driver: {message}", flush=True)


def record(**facts) -> None:
    RESULT.update(facts)
    with open(os.path.join(OUT, "result.json"), "w") as f:
        json.dump(RESULT, f, indent=1, default=str)


def properties_override():
    """window, area, region of a Properties editor switched to the Render tab (the limn panel)."""
    window = bpy.context.window_manager.windows[0]
    screen = window.screen
    area = next((a for a in screen.areas if a.type == "PROPERTIES"), None)
    if area is None:  # factory startup has one; make one out of the biggest other area otherwise
        area = max(screen.areas, key=lambda a: a.width * a.height)
        area.type = "PROPERTIES"
    area.spaces.active.context = "RENDER"
    region = next(r for r in area.regions if r.type == "WINDOW")
    return {"window": window, "screen": screen, "area": area, "region": region}


def call(op, *args, **kwargs):
    """Runs an operator as a click does (INVOKE_DEFAULT in the Properties editor); returns its
    result set, or the error message (str) when it reported an error."""
    with bpy.context.temp_override(**properties_override()):
        try:
            return op("INVOKE_DEFAULT", *args, **kwargs)
        except RuntimeError as e:
            return str(e)


def screenshot(name: str) -> str:
    """The whole X screen as OUT/name.png (imagemagick's import), when the tests ask for it."""
    import subprocess
    path = os.path.join(OUT, f"{name}.png")
    if os.environ.get("LIMN_WINDOW_SCREENSHOTS"):
        subprocess.run(["import", "-window", "root", path], check=False, timeout=30)
    return path


def quit_blender():
    log("quit_blender")
    record(quit_at=time.time())
    with bpy.context.temp_override(**properties_override()):
        bpy.ops.wm.quit_blender()


def main():
    record(pid=os.getpid(), started=time.time(), blender=bpy.app.version_string)
    import scenarios
    gen = getattr(scenarios, SCENARIO)(sys.modules[__name__])
    state = {"done": False}

    def step():
        if state["done"]:
            return None
        try:
            wait = next(gen)
        except StopIteration:
            state["done"] = True
            record(finished=True)
            quit_blender()
            return None
        except Exception:
            state["done"] = True
            record(error=traceback.format_exc())
            log("scenario failed:\n" + traceback.format_exc())
            quit_blender()
            return None
        return 0.05 if wait is None else float(wait)

    bpy.app.timers.register(step, first_interval=0.5, persistent=True)

