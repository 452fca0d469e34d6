"""The gain table: the one per-tick format any design's gains fill (`format`), its fixed-point
(Q15/Q31) quantization (`qformat`), its flash size (`flash`) and the C text the firmware
compiles (`codegen`). Imports no designer."""
