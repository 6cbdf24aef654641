"""The speech recogniser node: audio in, recognised text with confidence out on ``/pearl/speech``.

A thin rclpy layer over :mod:`pearl_pomdp.asr` (ROS-free): audio chunks go through the
VAD segmenter (:class:`~pearl_pomdp.asr.recognizer.UtteranceSegmenter`); each finished
utterance is decoded by a :class:`~pearl_pomdp.asr.recognizer.Recognizer` on the
language model generated from the domain's ``keywords:`` — in a worker thread, so a
decode never blocks the executor — and the result is published.

Audio message (docs/speech.md): ``std_msgs/Int16MultiArray`` of 16 kHz mono 16-bit PCM
samples, any chunk length (20–100 ms is usual). The rate may be declared in
``layout.dim[0].label`` as ``"samples@16000hz"`` (``pcm_to_msg`` does); a chunk that
declares another rate is dropped and counted (``wrong_rate``). An empty layout means
16 kHz. The utterance boundary is decided by voice activity, not by the chunking.

Output: ``pearl_interfaces/msg/RecognisedSpeech`` (text, confidence, stamp; ``publish_format:=typed``,
the default, what a domain's speech input reads) or a ``std_msgs/String`` of the bare text
(``publish_format:=text``, for consumers that read plain text; the confidence is lost). The JSON
``{"text", "confidence"}`` String of earlier versions is gone (bags that hold it still replay:
:func:`pearl_pomdp.speech.parse_speech_message`).

Parameters (read-only): see :attr:`SpeechRecognizerNode.PARAMETERS` (``ros2 param describe``).

Counters (on ``/diagnostics`` every ``diagnostics_period`` s): ``utterances`` decoded,
``published``, ``empty`` (speech with no words: not published unless ``publish_empty``),
``too_long`` (dropped by ``max_utterance_seconds``), ``wrong_rate`` and ``malformed`` chunks,
``overflow`` (utterances dropped because ``max_queue`` were already waiting), ``lost``
(chunks missing by the publisher's sequence numbers), ``clipped``
(utterances with > 1 % samples at full scale: decoded, and warned about).
"""
from __future__ import annotations

import queue
import re
import sys
import threading
from typing import Dict, List, Optional

import numpy as np
from std_msgs.msg import Int16MultiArray, MultiArrayDimension

from pearl_pomdp.nodes import conversions as cv
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pearl_pomdp.nodes.common import EVENT_QOS, NodeSetupError, Param, PearlNode, resolve_path, run_node

__all__ = ["SpeechRecognizerNode", "AudioMsg", "AUDIO_QOS", "pcm_to_msg", "msg_to_pcm", "main"]

#: The audio message type (common_interfaces has no audio message).
AudioMsg = Int16MultiArray
#: Audio chunks: reliable, volatile, keep-last 300 (30 s of 0.1 s chunks). A sentence sent
#: in a burst must not overwrite its own unacknowledged chunks (keep-last 20 lost words).
AUDIO_QOS = QoSProfile(depth=300, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
_RATE_LABEL = re.compile(r"(\d+)\s*hz", re.IGNORECASE)


def pcm_to_msg(pcm: np.ndarray, sample_rate: int = 16000) -> Int16MultiArray:
    """int16 samples as an ``Int16MultiArray`` with the rate in ``layout.dim[0].label``."""
    samples = np.asarray(pcm, dtype=np.int16)
    msg = Int16MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=f"samples@{int(sample_rate)}hz", size=len(samples),
                                          stride=len(samples))]
    msg.data = samples.tolist()
    return msg


def msg_to_pcm(msg: Int16MultiArray) -> "tuple[np.ndarray, Optional[int]]":
    """``(int16 samples, declared rate or None)`` of an audio message.

    Raises:
        ValueError: the layout declares a size that does not match the data, or a label
            names no rate in Hz.
    """
    samples = np.asarray(msg.data, dtype=np.int16)
    if not msg.layout.dim:
        return samples, None
    dim = msg.layout.dim[0]
    if dim.size and dim.size != len(samples):
        raise ValueError(f"layout.dim[0].size is {dim.size} but the message has {len(samples)} samples")
    if not dim.label:
        return samples, None
    m = _RATE_LABEL.search(dim.label)
    if m is None:
        raise ValueError(f"layout.dim[0].label {dim.label!r} names no sample rate (expected e.g. 'samples@16000hz')")
    return samples, int(m.group(1))


class SpeechRecognizerNode(PearlNode):
    """Audio (topic or microphone) → VAD → pocketsphinx → ``/pearl/speech`` (see the module doc).

    In-process use: ``SpeechRecognizerNode(parameter_overrides={...}, context=ctx)``;
    ``recognizer=`` passes a ready :class:`~pearl_pomdp.asr.recognizer.Recognizer`
    (saves building the model again).

    Raises:
        NodeSetupError: a bad parameter, a domain without keywords, pocketsphinx missing, or
            ``source:=microphone`` without a working input device.
    """

    DEFAULT_NAME = "speech_recognizer"
    PARAMETERS = (
        Param("domain", "config/pearl.domain.yaml", "Factored domain whose keywords: build the language model"),
        Param("language_model", "domain", "'domain' (keywords + filler path, fast) or 'default' (pocketsphinx en-us)"),
        Param("source", "topic", "'topic' (audio_topic) or 'microphone' (default input device via sounddevice)"),
        Param("device", "", "Input device name or index for source:=microphone ('' = system default)"),
        Param("audio_topic", "/pearl/audio_in", "Audio input (std_msgs/Int16MultiArray, 16 kHz mono PCM)"),
        Param("speech_topic", "/pearl/speech", "Recognised speech output (pearl_interfaces/RecognisedSpeech)"),
        Param("publish_format", "typed", "'typed' (pearl_interfaces/RecognisedSpeech: text, confidence) or "
                                         "'text' (std_msgs/String of the bare text)"),
        Param("publish_empty", False, "Publish utterances that decode to no words (as empty text, confidence 0)"),
        Param("max_utterance_seconds", 20.0, "Longer utterances are dropped (counted), not decoded",
              range=(0.5, 600.0)),
        Param("vad_window", 0.3, "Seconds of audio the endpointer judges speech/silence on", range=(0.03, 3.0)),
        Param("vad_ratio", 0.9, "Fraction of speech frames in the window that opens/closes an utterance",
              range=(0.1, 1.0)),
        Param("vad_mode", 0, "VAD aggressiveness, 0 (loose) to 3 (strict)", range=(0, 3)),
        Param("max_queue", 4, "Utterances that may wait for the decoder; more are dropped (counted)",
              range=(1, 100)),
        Param("diagnostics_period", 2.0, "Seconds between /diagnostics summaries", range=(0.05, 3600.0)),
    )

    def __init__(self, *, recognizer=None, **kwargs):
        super().__init__(**kwargs)
        p = self.declare_table(self.PARAMETERS)
        self.params = p
        for name, allowed in (("language_model", ("domain", "default")), ("source", ("topic", "microphone")),
                              ("publish_format", ("typed", "text"))):
            if p[name] not in allowed:
                raise NodeSetupError(f"parameter {name}: {p[name]!r} is not one of {', '.join(allowed)}")
        from pearl_pomdp.asr.recognizer import Recognizer, UtteranceSegmenter

        if recognizer is None:
            keywords = None
            if p["language_model"] == "domain":
                from pearl_pomdp.model.domain_yaml import load_domain

                domain = load_domain(resolve_path(p["domain"], "domain"))
                if not domain.keywords:
                    raise NodeSetupError(f"parameter domain: {domain.source} has no keywords: section")
                keywords = domain.keywords
            recognizer = Recognizer(keywords, max_seconds=p["max_utterance_seconds"])
        self.recognizer = recognizer
        self.segmenter = UtteranceSegmenter(window=p["vad_window"], ratio=p["vad_ratio"], vad_mode=p["vad_mode"],
                                            max_seconds=p["max_utterance_seconds"])
        self.counts: Dict[str, int] = {k: 0 for k in ("chunks", "utterances", "published", "empty", "too_long",
                                                     "wrong_rate", "malformed", "overflow", "clipped", "errors", "lost")}
        self._last_seq: Optional[int] = None
        self._closing = False
        self.last: List[dict] = []
        self._queue: "queue.Queue[Optional[np.ndarray]]" = queue.Queue(maxsize=p["max_queue"])
        self._feed_lock = threading.Lock()
        self.speech_pub = self.create_publisher(cv.RecognisedSpeechMsg if p["publish_format"] == "typed" else cv.TextMsg,
                                                p["speech_topic"], EVENT_QOS)
        self.diag_pub = self.create_publisher(cv.DiagnosticsMsg, "/diagnostics", EVENT_QOS)
        self._stream = None
        if p["source"] == "microphone":
            self._stream = self._open_microphone(p["device"])
        else:
            self.create_subscription(AudioMsg, p["audio_topic"], self._on_audio, AUDIO_QOS)
        self.create_timer(p["diagnostics_period"], self.publish_diagnostics)
        self._worker = threading.Thread(target=self._decode_loop, name="speech_decoder", daemon=True)
        self._worker.start()
        where = p["audio_topic"] if self._stream is None else f"microphone {p['device'] or '(default)'}"
        self.get_logger().info(f"listening on {where} with the {p['language_model']} language model "
                               f"({self.recognizer.identity}); publishing {p['publish_format']} on {p['speech_topic']}")

    # ------------------------------------------------------------ input
    def _open_microphone(self, device: str):
        try:
            import sounddevice
        except (ImportError, OSError) as err:
            raise NodeSetupError(f"parameter source:=microphone: sounddevice/PortAudio unavailable ({err}); "
                                 "pip install sounddevice and the PortAudio library, or use source:=topic") from None
        dev = int(device) if device.strip().isdigit() else (device or None)
        try:
            stream = sounddevice.InputStream(samplerate=16000, channels=1, dtype="int16", device=dev,
                                             blocksize=1600, callback=self._on_microphone)
            stream.start()
        except Exception as err:  # PortAudioError, ValueError: no such device
            raise NodeSetupError(f"parameter source:=microphone: no usable input device "
                                 f"{device or '(default)'}: {err}") from None
        return stream

    def _on_microphone(self, indata, frames, time_info, status) -> None:  # sounddevice thread
        self.feed(np.asarray(indata[:, 0], dtype=np.int16))

    def _on_audio(self, msg, info=None) -> None:
        self.counts["chunks"] += 1
        seq = info.get("publication_sequence_number") if isinstance(info, dict) else None
        if seq:  # gaps in the writer's sequence numbers: chunks lost on the way (one publisher)
            if self._last_seq is not None and seq > self._last_seq + 1:
                self.counts["lost"] += seq - self._last_seq - 1
                self.get_logger().warning(f"{self.params['audio_topic']}: {self.counts['lost']} audio chunk(s) lost "
                                          "so far", throttle_duration_sec=1.0)
            self._last_seq = seq
        try:
            pcm, rate = msg_to_pcm(msg)
        except ValueError as err:
            self.counts["malformed"] += 1
            self.get_logger().warning(f"{self.params['audio_topic']}: malformed audio chunk dropped: {err} "
                                      f"({self.counts['malformed']} so far)", throttle_duration_sec=1.0)
            return
        if rate is not None and rate != 16000:
            self.counts["wrong_rate"] += 1
            self.get_logger().warning(f"{self.params['audio_topic']}: chunk at {rate} Hz dropped; expected 16000 Hz "
                                      f"mono PCM ({self.counts['wrong_rate']} so far)", throttle_duration_sec=1.0)
            return
        self.feed(pcm)

    def feed(self, pcm: np.ndarray) -> None:
        """Add audio samples; finished utterances are queued for the decoder (never blocks)."""
        with self._feed_lock:
            before = self.segmenter.too_long
            utterances = self.segmenter.feed(pcm)
            dropped = self.segmenter.too_long - before
        if dropped:
            self.counts["too_long"] += dropped
            self.get_logger().warning(f"utterance longer than {self.params['max_utterance_seconds']:g} s dropped "
                                      f"({self.counts['too_long']} so far)", throttle_duration_sec=1.0)
        for u in utterances:
            try:
                self._queue.put_nowait(u)
            except queue.Full:
                self.counts["overflow"] += 1
                self.get_logger().warning(f"decoder busy: utterance dropped ({self.counts['overflow']} so far)",
                                          throttle_duration_sec=1.0)

    # ----------------------------------------------------------- decode
    def _decode_loop(self) -> None:
        from pearl_pomdp.asr.audio import AudioError

        while True:
            pcm = self._queue.get()
            if pcm is None:
                return
            try:
                rec = self.recognizer.recognise(pcm, where=self.params["audio_topic"])
            except AudioError as err:
                self.counts["too_long" if "longer" in str(err) else "errors"] += 1
                self.get_logger().warning(str(err), throttle_duration_sec=1.0)
                continue
            except Exception as err:  # noqa: BLE001 - a decoder failure must not end the node
                self.counts["errors"] += 1
                self.get_logger().error(f"decoding failed: {err}", throttle_duration_sec=1.0)
                continue
            self.counts["utterances"] += 1
            if rec.clipped > self.recognizer.clip_warning:
                self.counts["clipped"] += 1
                self.get_logger().warning(f"utterance clipped ({100 * rec.clipped:.1f} % of samples at full scale): "
                                          "lower the input gain", throttle_duration_sec=5.0)
            self.last = (self.last + [rec.to_dict()])[-10:]
            if not rec.text:
                self.counts["empty"] += 1
                if not self.params["publish_empty"]:
                    continue
            msg = (cv.speech_to_msg(rec.text, rec.confidence, stamp_s=self.now_s())
                   if self.params["publish_format"] == "typed" else cv.text_to_msg(rec.text))
            if self._closing or not self.context.ok():
                return
            try:
                self.speech_pub.publish(msg)
            except Exception:  # noqa: BLE001 - the node is being destroyed under us: stop quietly
                if self._closing or not self.context.ok():
                    return
                raise
            self.counts["published"] += 1
            self.get_logger().info(f"heard {rec.text!r} (confidence {rec.confidence:.2f}, "
                                   f"{rec.audio_seconds:.1f} s audio in {rec.decode_seconds:.2f} s)")

    def publish_diagnostics(self) -> None:
        """The counters on /diagnostics (WARN once anything was dropped)."""
        dropped = sum(self.counts[k] for k in ("too_long", "wrong_rate", "malformed", "overflow", "errors", "lost"))
        level = cv.DIAG_WARN if dropped else cv.DIAG_OK
        text = f"{dropped} input(s) dropped" if dropped else "listening"
        self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: {self.get_name()}", self.recognizer.identity, level,
                                                    text, dict(self.counts), self.now_s()))

    def destroy_node(self):
        self._closing = True
        if self._stream is not None:
            try:
                self._stream.stop()
                self._stream.close()
            except Exception:  # noqa: BLE001 - closing a vanished device is not an error at shutdown
                pass
        try:
            self._queue.put_nowait(None)
        except queue.Full:
            pass
        return super().destroy_node()


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``speech_recognizer`` (``--ros-args -p name:=value``)."""
    return run_node(SpeechRecognizerNode, args)


if __name__ == "__main__":
    sys.exit(main())
