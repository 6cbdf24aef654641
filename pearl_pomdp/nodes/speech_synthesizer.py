"""The speech synthesiser node: ``/pearl/say`` text → espeak-ng audio (device or topic).

A thin rclpy layer over :class:`pearl_pomdp.asr.synthesizer.Synthesizer`. Each sentence
is synthesised in a worker thread (the executor never waits for espeak or the sound
card) and sent to

* ``output:=topic`` (default): ``audio_topic`` as ``std_msgs/Int16MultiArray`` chunks of
  ``chunk_seconds`` of 16 kHz mono PCM (the recogniser's input format, docs/speech.md),
  published as fast as they are made; a sentence's chunks are consecutive and followed by
  ``pause_seconds`` of silence;
* ``output:=device``: the default (or ``device``) output device through ``sounddevice``.
  With no device the node does not start: one error line naming the parameter;
* ``output:=none``: synthesised and counted only (a dry run of the voice settings).

In simulation the resident hears the text on ``/pearl/say`` directly; this node is for
a robot with a speaker. A sentence longer than
:data:`~pearl_pomdp.asr.synthesizer.MAX_TEXT_CHARS` or arriving while ``max_queue``
sentences wait is dropped and counted; an unknown voice is a start-up error.
"""
from __future__ import annotations

import queue
import sys
import threading
from typing import Any, Dict, List, Optional

import numpy as np

from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.common import EVENT_QOS, NodeSetupError, Param, PearlNode, run_node
from pearl_pomdp.nodes.speech_recognizer import AUDIO_QOS, AudioMsg, pcm_to_msg

__all__ = ["SpeechSynthesizerNode", "main"]


class SpeechSynthesizerNode(PearlNode):
    """``/pearl/say`` → espeak-ng → output device or audio topic (see the module doc).

    Raises:
        NodeSetupError: an unknown voice or output, espeak-ng missing, or ``output:=device``
            with no output device.
    """

    DEFAULT_NAME = "speech_synthesizer"
    PARAMETERS = (
        Param("say_topic", "/pearl/say", "Sentences to speak (std_msgs/String)"),
        Param("output", "topic", "'topic' (audio_topic), 'device' (sound card via sounddevice) or 'none'"),
        Param("audio_topic", "/pearl/audio_out", "Audio output for output:=topic (std_msgs/Int16MultiArray, 16 kHz)"),
        Param("device", "", "Output device name or index for output:=device ('' = system default)"),
        Param("voice", "en-us", "espeak-ng voice name (en-us, en, en-gb-x-rp, en-us+f3 ...) or a preset (clear, slow ...)"),
        Param("rate", 150, "Words per minute (slower is easier for elderly listeners)", range=(80, 450)),
        Param("pitch", 50, "Pitch 0-100", range=(0, 100)),
        Param("volume", 100, "Volume 0-200", range=(0, 200)),
        Param("pause_seconds", 0.5, "Silence sent after each sentence (output:=topic): ends the utterance "
              "for a listener's voice-activity detector", range=(0.0, 10.0)),
        Param("chunk_seconds", 0.1, "Seconds of audio per published chunk (output:=topic)", range=(0.01, 10.0)),
        Param("max_queue", 8, "Sentences that may wait to be spoken; more are dropped (counted)", range=(1, 1000)),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        p = self.declare_table(self.PARAMETERS)
        self.params = p
        if p["output"] not in ("topic", "device", "none"):
            raise NodeSetupError(f"parameter output: {p['output']!r} is not one of topic, device, none")
        from pearl_pomdp.asr.synthesizer import VOICES, Synthesizer, Voice

        base = VOICES.get(p["voice"])
        self.voice = (Voice(base.name, rate=p["rate"], pitch=p["pitch"], pitch_range=base.pitch_range,
                            volume=p["volume"], word_gap=base.word_gap) if base is not None
                      else Voice(p["voice"], rate=p["rate"], pitch=p["pitch"], volume=p["volume"]))
        self.synth = Synthesizer.instance()
        try:
            self.synth.synthesize("ok", self.voice)  # an unknown voice fails here, at start-up
        except Exception as err:
            raise NodeSetupError(f"parameter voice: {err}") from None
        self._sd: Any = None   # the sounddevice module, for output:=device
        if p["output"] == "device":
            self._sd = self._check_device(p["device"])
        self.counts: Dict[str, int] = {"sentences": 0, "spoken": 0, "dropped": 0, "errors": 0, "samples": 0}
        self._queue: "queue.Queue[Optional[str]]" = queue.Queue(maxsize=p["max_queue"])
        self.audio_pub: Any = (self.create_publisher(AudioMsg, p["audio_topic"], AUDIO_QOS)
                               if p["output"] == "topic" else None)
        self.create_subscription(cv.TextMsg, p["say_topic"], self._on_say, EVENT_QOS)
        self._worker = threading.Thread(target=self._speak_loop, name="speech_synth", daemon=True)
        self._worker.start()
        self.get_logger().info(f"speaking {p['say_topic']} with voice {self.voice.name} at {self.voice.rate} wpm "
                               f"to {p['output'] if p['output'] != 'topic' else p['audio_topic']}")

    def _check_device(self, device: str):
        try:
            import sounddevice
        except (ImportError, OSError) as err:
            raise NodeSetupError(f"parameter output:=device: sounddevice/PortAudio unavailable ({err}); "
                                 "use output:=topic") from None
        dev = int(device) if device.strip().isdigit() else (device or None)
        try:
            sounddevice.check_output_settings(device=dev, samplerate=16000, channels=1, dtype="int16")
        except Exception as err:  # PortAudioError / ValueError: no such device
            raise NodeSetupError(f"parameter output:=device: no usable output device {device or '(default)'}: "
                                 f"{err}") from None
        self._device = dev
        return sounddevice

    def _on_say(self, msg) -> None:
        text = cv.msg_to_text(msg).strip()
        if not text:
            return
        self.counts["sentences"] += 1
        try:
            self._queue.put_nowait(text)
        except queue.Full:
            self.counts["dropped"] += 1
            self.get_logger().warning(f"{self.params['say_topic']}: {self.params['max_queue']} sentences waiting; "
                                      f"dropped {text[:40]!r} ({self.counts['dropped']} so far)",
                                      throttle_duration_sec=1.0)

    def _speak_loop(self) -> None:
        while True:
            text = self._queue.get()
            if text is None:
                return
            try:
                pcm = self.synth.synthesize(text, self.voice)
            except Exception as err:  # noqa: BLE001 - SynthesisError (too long ...): count, keep running
                self.counts["dropped"] += 1
                self.get_logger().warning(f"{self.params['say_topic']}: cannot speak {text[:40]!r}: {err}",
                                          throttle_duration_sec=1.0)
                continue
            try:
                emitted = self._emit(pcm)
            except Exception as err:  # noqa: BLE001 - a device that vanished mid-run: count, keep running
                self.counts["errors"] += 1
                self.get_logger().error(f"audio output failed: {err}", throttle_duration_sec=5.0)
                continue
            self.counts["samples"] += emitted
            self.counts["spoken"] += 1

    def _emit(self, pcm: np.ndarray) -> int:
        """Send one sentence's samples; returns how many were sent."""
        if self.params["output"] == "topic":
            step = max(1, int(self.params["chunk_seconds"] * 16000))
            pcm = np.concatenate([pcm, np.zeros(int(self.params["pause_seconds"] * 16000), dtype=np.int16)])
            for i in range(0, len(pcm), step):
                if not self.context.ok():
                    return i
                self.audio_pub.publish(pcm_to_msg(pcm[i:i + step]))
        elif self.params["output"] == "device":
            self._sd.play(pcm, samplerate=16000, device=self._device, blocking=True)
        return len(pcm)

    def destroy_node(self):
        try:
            self._queue.put_nowait(None)
        except queue.Full:
            pass
        return super().destroy_node()


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``speech_synthesizer`` (``--ros-args -p name:=value``)."""
    return run_node(SpeechSynthesizerNode, args)


if __name__ == "__main__":
    sys.exit(main())
