"""ZMP CarriRo AD+ external serial interface, API reference v1.4 (firmware V1.16.0.x).

Source: the CarriRo AD+ serial API reference v1.4; sections are cited by their headings.
RS-232C, 19200 bps, 8 data bits, even parity, 1 stop bit (インターフェイス仕様). Commands are ASCII
lines, `name?` (get) or `name: <params>` (set), parameters separated by spaces, LF-terminated, at
most 255 characters (コマンド形式). Replies repeat the command's head (コマンドレスポンス); errors
are `name: error 1|2|3` (エラーコード).

Modules: `carriro_tables` (Appendix A-G as data, field types), `carriro_codec` (`CarriroCodec`),
`carriro_device` (`CarriroDevice`). This module registers them as "carriro".

Readings where the document is unclear or contradicts itself (each is the default; several are
settings of the device):

Wire format
- 255 characters (コマンド形式) count the characters before the LF. A longer line is answered
  when its LF arrives: `<name>: error 2` if it starts with a known command, else `error 1`
  (our reading: over-long lines are errors).
- Error replies always use `:` (`battery: error 2`), as the エラーコード format shows, even for
  get commands. The name is the line's text up to its first `?`, `:` or space; bytes outside
  printable ASCII are written as Python escapes (`\\xff`, `\\r`); an empty line answers
  `: error 1`. The name is cut so that the reply stays within 255 characters.
- Precedence: error 1 (name or form) before 2 (data) before 3 (state).
- A get-only command sent with `:` (`battery: 5`), a set-only one with `?` (`reboot?`), and
  `ad_output?` ("外部からのコマンドとして使用できません", ad_output?) are error 1: the
  コマンドリスト defines each command with its type.
- The name is followed directly by `?`/`:`; parameters follow one space (`comm:20` is error 2);
  runs of spaces between parameters are accepted. Only LF ends a line; a CR is a bad character
  (error 2), so CRLF hosts are caught.
- echo: returns its parameters "そのまま": the exact text after `echo: `, spacing included.
  A reply `echo: error 1` is decoded as an error: on the wire the two cannot be told apart.
- Values are in the document's units: a field with 倍率 10 or 100 decodes to a float (km/h, m,
  s), 倍率 1 to an int; encoding rejects values that are not whole raw steps (2.05 km/h).

Commands
- ad_speed_limit: its examples say `speed_limit?` / `speed_limit: 20`. Both names are accepted
  and the reply uses the name the host used; `CarriroDevice(speed_limit_alias=False)` answers
  the short name with error 1.
- action: Appendix A lists only 1 (緊急停止), yet the example is `action: 2` -> `action: 2`. The
  codec accepts any non-negative ID; the device accepts `action_ids` (default Appendix A: {1})
  and answers error 2 otherwise. `action_ids={1, 2}` reproduces the example.
- mode: the example says `mode: 10` sets 自律; Appendix G says 10 is 右Uターン and 11 is 自律.
  Appendix G wins (the example's bytes still round-trip: 10 is settable).
- mode: a Get-only or unknown mode is error 2 (outside the settable 範囲). From a settable mode
  (5, 8-11) any settable mode may be set; from 充電中, ワーニング, ドライブ, ニュートラル (2, 3, 6,
  7) only パーキング (warning? 注記: parking clears warnings); from 不明, 初期化, エラー,
  パレット台車接続 (0, 1, 4, 12) none (error? 注記: errors clear only by restart): error 3.
- reboot:, shutdown: only in parking or error mode (注記), else error 3. `OK` is sent first;
  then the vehicle restarts (banner after `startup_s`) or stays off until `power_on`.
- action: 1 (緊急停止) is accepted in every mode, as are ad_pattern:, ad_speed_limit:, comm:,
  echo:, status_cmd: and every get command: the document restricts none of them.
- ad_action: only in autonomous mode (11), else error 3; IDs outside Appendix C are error 2.
  0 and 9 stop (ad_status 4), 14 resumes (ad_status 2), 16 reverses (ad_status 3); the action
  runs with its fixed or デフォルト parameters (9: 130 cm).
- ad_action? gives the ID; with -p the ID and all its Appendix B parameters (none for actions
  without parameters). Appendix B has no 20, 22, 23: those IDs are invalid. 保留 IDs (32, 35-39)
  are valid and have no parameters. Before any action the device reports 0 (no value given).
- Appendix B action 19 points to "Appendix E" for its landmark: read as Appendix F's fixed IDs
  (0-19, 255). Action 29 parameter 3 says radius 1 m for 5, 6 and 7: read as 1, 2, 3 m (no wire
  effect). Actions 17 and 34: the distance range depends on the direction and is enforced.
- dist?, ad_landmark?: 範囲 0-2147483648 is taken as written (one above the int32 maximum).
- status_cmd: the command is known, so a bad list (an unknown name, status? or status_cmd?, a
  set form, an option such as -p, none or more than 15) is error 2; the list is then unchanged
  (注記). ad_action? in the list gives the ID only. A `status?` reply longer than 255 characters
  is cut there (注記); the codec cannot decode a cut reply.
- speed? 範囲 is 0, 5-30: the device reports speeds under 0.5 km/h as 0.
- error?, warning?: 8 upper-case hex digits; codes missing from Appendix E are still accepted on
  the wire (`carriro_tables.describe_code` returns None for them). id?: 12 printable characters.

Device behaviour and assumed figures
- 処理: from a command's LF until its reply is sent, input is ignored; the reply comes
  `processing_s` (assumed 5 ms) after the LF. The host must wait 10 ms after a reply; the device
  models the reason by ignoring input for `quiet_after_reply_s` (10 ms) more, so a host that
  breaks the rule loses its command (0 gives the other reading).
- スタートアップ: input is ignored until the banner `CarriRo AD+ 1.16.0.2`, sent `startup_s`
  (assumed 1 s; "しばらくかかります") after power-on or reboot. The version? example shows
  1.12.0.0; one `version` setting (default the banner's) serves both.
- comm: the first periodic `status?` comes one period after the comm: reply, then every period.
- A restart resets ad_pattern, comm, status_cmd (their 注記), error (error? 注記), warning,
  dist (起動後から), the speed limit (30) and the mode (parking); battery and the
  pallet/trolley flags are physical and kept.
- `raise_code`: an Appendix E error puts the vehicle in エラー (4), a warning in ワーニング (3),
  speed 0; ad_status becomes 7 / 6 (Appendix D) if it was autonomous.
- Entering autonomous mode: ad_status 2, action 4 (直進3, 3.0 km/h) capped by the speed limit.
  Any other mode: speed 0, ad_status 1. Motion itself belongs to the device's owner.
"""

from __future__ import annotations

from agv_model.protocols.base import register
from agv_model.protocols.carriro_codec import (
    BANNER,
    DEFAULT_STATUS_CMDS,
    DONE,
    ERROR,
    VALUE,
    CarriroCodec,
    CarriroError,
)
from agv_model.protocols.carriro_device import CarriroDevice, CarriroState

__all__ = ["BANNER", "DEFAULT_STATUS_CMDS", "DONE", "ERROR", "VALUE", "CarriroCodec",
           "CarriroDevice", "CarriroError", "CarriroState"]

register("carriro", CarriroCodec, CarriroDevice)
