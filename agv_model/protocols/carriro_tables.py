"""CarriRo AD+ serial API v1.4: the document's tables as data, and the field types of its values.

Every figure here is taken from the CarriRo AD+ serial API reference v1.4; the section is named
beside it. The readings where the document is unclear are listed in `agv_model.protocols.carriro`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final, Literal

Value = int | float | str

# "コマンドは最大255文字列です" (コマンド形式); the LF terminator is not counted.
MAX_LINE_CHARS: Final = 255
TERMINATOR: Final = b"\n"  # "改行文字(ASCII code 0x0A)" (コマンド形式)
ERROR_UNKNOWN_COMMAND: Final = 1  # エラーコード table
ERROR_INVALID_DATA: Final = 2
ERROR_INVALID_STATE: Final = 3
STATUS_CMD_MAX: Final = 15  # "最大で15コマンドを追加可能です" (status_cmd:)
NO_CODE: Final = "00000000"  # "エラー、ワーニングなし" (Appendix E)
MODEL_NAME: Final = "CarriRo AD+"  # start-up banner (スタートアップ)
BANNER_VERSION: Final = "1.16.0.2"  # start-up banner (スタートアップ)


class FieldError(ValueError):
    """A value or token that does not fit its field; the message says what was expected."""


@dataclass(frozen=True)
class IntField:
    """An integer on the wire. `ranges` hold raw (wire) values, inclusive, as the document's
    範囲 rows do; `scale` is its 倍率: a scaled field's value is raw / scale, in `unit`."""

    name: str
    ranges: tuple[tuple[int, int], ...]
    scale: int = 1
    unit: str = ""
    default: int | None = None  # raw default (デフォルト rows), documentation only

    def expected(self) -> str:
        spans = ", ".join(str(lo) if lo == hi else f"{lo}-{hi}" for lo, hi in self.ranges)
        scaled = f", scale {self.scale}" if self.scale != 1 else ""
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.name}: an integer in {spans} (raw{scaled}{unit})"

    def _check(self, raw: int) -> int:
        if not any(lo <= raw <= hi for lo, hi in self.ranges):
            raise FieldError(self.expected())
        return raw

    def decode(self, token: str) -> Value:
        if not re.fullmatch(r"-?[0-9]+", token):
            raise FieldError(self.expected())
        raw = self._check(int(token))
        return raw if self.scale == 1 else raw / self.scale

    def encode(self, value: object) -> str:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise FieldError(self.expected())
        scaled = value * self.scale
        raw = round(scaled)
        if abs(scaled - raw) > 1e-6:
            raise FieldError(f"{self.expected()}; {value!r} is not a multiple of 1/{self.scale}")
        return str(self._check(raw))


@dataclass(frozen=True)
class TextField:
    """A string on the wire that must match `pattern` whole."""

    name: str
    pattern: str
    meaning: str

    def expected(self) -> str:
        return f"{self.name}: {self.meaning}"

    def decode(self, token: str) -> Value:
        if not re.fullmatch(self.pattern, token):
            raise FieldError(self.expected())
        return token

    def encode(self, value: object) -> str:
        if not isinstance(value, str) or not re.fullmatch(self.pattern, value):
            raise FieldError(self.expected())
        return value


Field = IntField | TextField

# Appendix A - キャリロアクション (for action:)
CARRIRO_ACTIONS: Final[dict[int, str]] = {1: "緊急停止"}

# Appendix D - 自律モードステータス
AD_STATUSES: Final[dict[int, str]] = {
    1: "自律モードではない",
    2: "移動中",
    3: "後退中",
    4: "停止アクションにより停止",
    5: "障害物により停止",
    6: "ワーニングモード",
    7: "エラーモード",
}

# Appendix G - 操作モード: code -> (name, settable with mode:)
MODES: Final[dict[int, tuple[str, bool]]] = {
    0: ("不明", False),
    1: ("初期化", False),
    2: ("充電中", False),
    3: ("ワーニング", False),
    4: ("エラー", False),
    5: ("パーキング", True),
    6: ("ドライブ", False),
    7: ("ニュートラル", False),
    8: ("カルガモ", True),
    9: ("左Uターン", True),
    10: ("右Uターン", True),
    11: ("自律", True),
    12: ("パレット台車接続", False),
}
MODE_WARNING: Final = 3
MODE_ERROR: Final = 4
MODE_PARKING: Final = 5
MODE_AUTONOMOUS: Final = 11

# Appendix F - ランドマークID: fixed IDs, then 20-97 named A..Z, A1..Z1, A2..Z2.
_FIXED_LANDMARKS: Final = {
    255: "未設定", 0: "緊急停止", 1: "直進1", 2: "直進2", 3: "直進3", 4: "左カーブターン",
    5: "右カーブターン", 6: "左Uターン", 7: "右Uターン", 8: "一時停止", 9: "カルガモモード",
    10: "左旋回", 11: "右旋回", **{i: "システム使用済み" for i in range(12, 20)},
}
LANDMARKS: Final[dict[int, str]] = {
    **_FIXED_LANDMARKS,
    **{20 + 26 * row + col: chr(ord("A") + col) + ("", "1", "2")[row]
       for row in range(3) for col in range(26)},
}
LANDMARK_UNSET: Final = 255

# Appendix B - 自律モードアクション. Shared parameter shapes first.
_STOP_CM = IntField("stop_distance_cm", ((50, 255),), unit="cm", default=130)
_ACTION_AFTER = IntField("action_after", ((0, 4),))  # 0 前進 1 左旋回 2 右旋回 3 左U 4 右U
_DIRECTION = IntField("direction", ((0, 1),))  # 0 前進, 1 後退
_NO_PARAMS: tuple[Field, ...] = ()


@dataclass(frozen=True)
class AdAction:
    """One row group of Appendix B: an autonomous action and its parameters, in order."""

    action_id: int
    name: str
    params: tuple[Field, ...] = _NO_PARAMS


def _straight(action_id: int, name: str, raw: int) -> AdAction:
    speed = IntField("speed_kmh", ((raw, raw),), scale=10, unit="km/h")  # パラメーター(固定)
    return AdAction(action_id, name, (speed,))


def _turn(action_id: int, name: str, fixed_angle: bool) -> AdAction:
    angle = (IntField("turn_angle_deg", ((180, 180),), unit="deg") if fixed_angle
             else IntField("turn_angle_deg", ((10, 180),), unit="deg", default=90))
    return AdAction(action_id, name, (_STOP_CM, angle))


def _curve(action_id: int, name: str) -> AdAction:
    radius = IntField("turn_radius_m", ((10, 30),), scale=10, unit="m", default=10)
    return AdAction(action_id, name, (radius,))


_BINARY5 = r"[01]{5}"
AD_ACTIONS: Final[dict[int, AdAction]] = {a.action_id: a for a in (
    AdAction(0, "緊急停止"),
    AdAction(1, "直進", (IntField("speed_kmh", ((5, 30),), scale=10, unit="km/h"),)),
    _straight(2, "直進1", 10),
    _straight(3, "直進2", 20),
    _straight(4, "直進3", 30),
    _turn(5, "左旋回", fixed_angle=False),
    _turn(6, "右旋回", fixed_angle=False),
    _turn(7, "左Uターン", fixed_angle=True),
    _turn(8, "右Uターン", fixed_angle=True),
    AdAction(9, "一時停止", (_STOP_CM,)),
    AdAction(10, "時間待機", (IntField("wait_s", ((5, 60),), unit="s"),)),
    _curve(11, "左カーブターン"),
    _curve(12, "右カーブターン"),
    AdAction(13, "外部出力", (
        TextField("output_mask", _BINARY5, "five binary digits 00000-11111"),
        TextField("output_value", _BINARY5, "five binary digits 00000-11111"),
        IntField("pulse_s", ((0, 255),), scale=10, unit="s"),
        IntField("pause_s", ((0, 255),), unit="s"),
    )),
    AdAction(14, "一時停止からの再開"),
    AdAction(15, "カルガモモード"),
    AdAction(16, "後退"),
    AdAction(17, "パレット切り離し", (
        _STOP_CM, _DIRECTION,
        IntField("distance_m", ((12, 50),), scale=10, unit="m"),  # 前進 12-50, 後退 17-50
        _ACTION_AFTER,
    )),
    AdAction(18, "パレット接続", (
        _STOP_CM, _DIRECTION, IntField("distance_m", ((0, 50),), scale=10, unit="m"),
        _ACTION_AFTER,
    )),
    AdAction(19, "距離制限", (
        IntField("search_distance_m", ((0, 255),), scale=10, unit="m"),
        IntField("fixed_landmark_id", ((0, 19), (255, 255))),
    )),
    AdAction(21, "Robo-Hi 一時停止", (_STOP_CM,)),
    AdAction(24, "ライントレース 前進"),
    AdAction(25, "ライントレース 後退"),
    AdAction(26, "ライントレース 一時停止"),
    AdAction(27, "ユーザーによる一時停止"),
    AdAction(28, "台車切り離し"),
    AdAction(29, "台車接続", (
        _STOP_CM,
        IntField("action_before", ((1, 4),)),
        IntField("action_after", ((0, 7),)),
        IntField("forward_before_curve_cm", ((0, 250),), unit="cm"),
    )),
    AdAction(30, "自動充電", (
        _STOP_CM, IntField("action_to_station", ((0, 4),)),
        IntField("leave_distance_m", ((-50, 50),), scale=10, unit="m"), _ACTION_AFTER,
    )),
    AdAction(31, "パレット接続もしくはパレット接続なしで走行続行", (
        IntField("distance_connected_m", ((-50, 50),), scale=10, unit="m"), _ACTION_AFTER,
        IntField("distance_not_found_m", ((-80, 80),), scale=10, unit="m"), _ACTION_AFTER,
    )),
    AdAction(32, "保留"),
    AdAction(33, "Robo-Hi ライントレース 一時停止",
             (IntField("stop_distance_cm", ((50, 5000),), unit="cm"),)),
    AdAction(34, "パレット切り離し長距離", (
        IntField("stop_distance_m", ((5, 80),), scale=10, unit="m", default=13), _DIRECTION,
        IntField("distance_m", ((12, 100),), scale=10, unit="m"),  # 前進 12-50, 後退 17-100
        _ACTION_AFTER,
    )),
    *(AdAction(i, "保留") for i in range(35, 40)),
)}

# Appendix B, actions 17 and 34: the distance range depends on the direction (raw values).
_DETACH_DISTANCE: Final[dict[tuple[int, int], tuple[int, int]]] = {
    (17, 0): (12, 50), (17, 1): (17, 50), (34, 0): (12, 50), (34, 1): (17, 100),
}


def check_action_params(action_id: int, params: tuple[Value, ...]) -> None:
    """The cross-parameter rule of actions 17 and 34 (Appendix B): 前進 and 後退 differ."""
    if action_id not in (17, 34) or len(params) != 4:
        return
    direction, distance = params[1], params[2]
    lo, hi = _DETACH_DISTANCE[(action_id, int(direction))]
    raw = round(float(distance) * 10)
    if not lo <= raw <= hi:
        way = "前進" if direction == 0 else "後退"
        raise FieldError(f"distance_m: raw {lo}-{hi} (scale 10, m) when direction is {way}")


def default_params(action_id: int) -> tuple[Value, ...]:
    """The parameters an action runs with when set by `ad_action:` alone (fixed or デフォルト)."""
    values: list[Value] = []
    for field in AD_ACTIONS[action_id].params:
        if not isinstance(field, IntField):
            raise ValueError(f"action {action_id} has no default for {field.name}")
        fixed = field.ranges[0] if field.ranges[0][0] == field.ranges[0][1] else None
        raw = field.default if field.default is not None else fixed[0] if fixed else None
        if raw is None:
            raise ValueError(f"action {action_id} has no default for {field.name}")
        values.append(raw if field.scale == 1 else raw / field.scale)
    return tuple(values)


# Appendix C - 設定可能な自律モードアクション (ad_action:)
SETTABLE_AD_ACTIONS: Final[dict[int, str]] = {
    0: "緊急停止", 9: "一時停止", 14: "一時停止からの再開", 16: "後退",
}

# Appendix E - エラーとワーニングコード, row by row: code, level, meaning. "xx" is any hex byte.
Level = Literal["None", "Info", "Error", "Warning"]
_CODE_TABLE: Final = """
00000000 None エラー、ワーニングなし
01010000 Info -----キャリロ電源オン-----
01020000 Error モジュール初期化エラー
01030000 Error キャリロ初期化エラー
01040000 Error キャリブレーションデータ読み込み失敗
01050000 Error UIバーキャリブレーション失敗
01060000 Error 左カメラキャリブレーション異常
01070000 Error 右カメラキャリブレーション異常
01080000 Error スタックオーバーフロー
01090000 Error メモリ確保異常
010A0000 Error ファイルシステムマウント異常
010B0000 Error 緊急停止スイッチが押下されました
01800000 Warning モーター過負荷を検知
01810000 Warning パーキング以外で充電器の接続を検知しました
01820000 Warning バッテリー残量が低すぎます
01830000 Warning バッテリー温度が低すぎます
01840000 Warning バッテリー温度が高すぎます
01850000 Warning 操作モード切替スイッチが中間位置です
01860000 Warning カルガモ左モーター不安定
01870000 Warning カルガモ右モーター不安定
01880000 Warning ドライブ左モーター不安定
01890000 Warning ドライブ右モーター不安定
018A0000 Warning 左モーター回転異常
018B0000 Warning 右モーター回転異常
018C0000 Warning 左モーター速度指示差異常
018D0000 Warning 右モーター速度指示差異常
018E0000 Warning 自律モードが終了しました
018F0000 Warning 緊急停止スイッチが押されました
01900000 Warning バンパーセンサが動作しました
01910000 Warning パレット台車が見つかりませんでした
01920000 Warning パレット台車接続タイムアウト
01930000 Warning パレット台車が既に接続されています
03010000 Error BMS通信タイムアウト
0B010000 Error IMU初期化エラー
0B020000 Error IMU値固着エラー
0C010000 Error IFボード通信タイムアウト
0C020000 Error マーカカメラ通信タイムアウト
10020000 Error リモートIMU通信タイムアウト
12010000 Error FPGA初期化タイムアウト
12020000 Error ビーコンID初期化失敗
12030000 Error ビーコンID書き込み失敗
12040000 Error ステレオカメラモジュールエラー
13010000 Info SysLogオーバーフロー
14010000 Error UIバー RXタイムアウト
14020000 Error UIバーキャリブレーションエラー
14030000 Error UIスタビリゼーションエラー
1B010000 Warning ランドマークが検出されませんでした
1B020000 Warning 目標位置が設定されていません
1B030000 Warning 緊急停止ランドマークが検出されました
1B040000 Warning パレット台車が検出されませんでした
1B050000 Warning パレット台車接続タイムアウト
1B060000 Warning パレット台車が既に接続されています
1B070000 Warning 牽引台車インタフェースがありません
1B080000 Warning 牽引台車が切り離せませんでした
1B090000 Warning 充電ステーションアクセス距離オーバー
1B0C0000 Warning 牽引台車が既に接続されています
1B0D0000 Warning 牽引台車接続できませんでした
1B0E0000 Warning 牽引台車が外れました
1F010000 Error 左モータードライバコントローラ過熱
1F010001 Error 右モータードライバコントローラ過熱
1F020000 Error 左モータースピード超過
1F020001 Error 右モータースピード超過
1F030000 Error 左モータードライバ低電圧
1F030001 Error 右モータードライバ低電圧
1F040000 Error 左モータードライバ過電圧
1F040001 Error 右モータードライバ過電圧
1F050000 Error 左モーターストール
1F050001 Error 右モーターストール
1F060000 Error 左モーターセンサーエラー
1F060001 Error 右モーターセンサーエラー
1F070000 Error 左モータードライバ CAN通信エラー
1F070001 Error 右モータードライバ CAN通信エラー
1F080000 Error 左モーター 過熱
1F080001 Error 右モーター 過熱
1F090000 Error 左モータードライバシステムエラー
1F090001 Error 右モータードライバシステムエラー
1F0A0000 Error 左モータードライバ過電流
1F0A0001 Error 右モータードライバ過電流
1F0B0000 Error 左モータードライバICエラー
1F0B0001 Error 右モータードライバICエラー
1F7D0000 Error 左モーター CAN通信エラー
1F7D0001 Error 右モーター CAN通信エラー
1F7F0000 Error 左モータードライバ不明エラー
1F7F0001 Error 右モータードライバ不明エラー
1F810000 Warning 左モータードライバコントローラ過熱
1F810001 Warning 右モータードライバコントローラ過熱
1F820000 Warning 左モータースピード超過
1F820001 Warning 右モータースピード超過
1F830000 Warning 左モータードライバ低電圧
1F830001 Warning 右モータードライバ低電圧
1F840000 Warning 左モータードライバ過電圧
1F840001 Warning 右モータードライバ過電圧
1F850000 Warning 左モーターストール
1F850001 Warning 右モーターストール
1F860000 Warning 左モーター過熱
1F860001 Warning 右モーター過熱
1FFF0000 Warning 左モータードライバ不明エラー
1FFF0001 Warning 右モータードライバ不明エラー
20010000 Error LRFデータ取得タイムアウト
20020000 Error LRF初期設定失敗
21020000 Error パレットIF 通信タイムアウト
21030000 Error パレットIF セルフテストタイムアウト
21040000 Error パレットIF リフト機構セルフテスト失敗
21050000 Error パレットIF フックセルフテスト失敗
24010000 Error LRFデータ取得タイムアウト
24020000 Error LRF初期設定失敗
25000000 Error BMSセル電圧不足
25010000 Warning BMSセル電圧不足
25020000 Error BMSセル電圧過剰
25030000 Warning BMSセル電圧過剰
25040000 Error BMS高温超過
25050000 Warning BMS高温超過
25060000 Error BMS低温超過
25070000 Warning BMS低温超過
25080000 Error BMS充電過電流
25090000 Warning BMS充電過電流
250A0000 Error BMS充電過放電電流
250B0000 Warning BMS充電過放電電流
250C0000 Error BMS内部コミュニケーションエラー
25100000 Warning BMSパック電圧不足
25110000 Error BMSパック電圧不足
25120000 Warning BMSパック電圧過剰
25130000 Error BMSパック電圧過剰
25800000 Error BMSコミュニケーションタイムアウト
258100xx Error BMS CPU自己診断エラー
258200xx Error BMS回路自己診断エラー
26020000 Error Trolley IF: コミュニケーションタイムアウト
26030000 Error Trolley IF: セルフテストタイムアウト
26040000 Error Trolley IF: リフトアクチュエーターセルフテスト失敗
26050000 Error Trolley IF: ユニットアクチュエーターセルフテスト失敗
27020000 Error UART Switcher: コミュニケーションタイムアウト
28020000 Error VSLAM: CANUSBZ コミュニケーションタイムアウト
"""


def _parse_codes(table: str) -> dict[str, tuple[Level, str]]:
    levels: dict[str, Level] = {"None": "None", "Info": "Info", "Error": "Error",
                                "Warning": "Warning"}
    rows = (line.split(" ", 2) for line in table.strip().splitlines())
    return {code: (levels[level], meaning) for code, level, meaning in rows}


CODES: Final[dict[str, tuple[Level, str]]] = _parse_codes(_CODE_TABLE)


def describe_code(code: str) -> tuple[Level, str] | None:
    """Level and meaning of an Appendix E code, or None when the table does not list it."""
    if code in CODES:
        return CODES[code]
    return CODES.get(code[:6] + "xx") if re.fullmatch(r"[0-9A-F]{8}", code) else None
