// Every string the page shows, in English and Simplified Chinese, and the one lookup t().
//
// Elements carry data-i18n (text), data-i18n-aria (aria-label) or data-i18n-title (tooltip) with
// a key of STRINGS; applyStrings() fills them. Messages the server sends in English (reasons,
// faults, refusals) are put into the page's language by translateServer(): alarm and error
// codes by number, the rest by the patterns below. A text no pattern knows is shown as sent.

export const LANGUAGES = { en: "English", zh: "中文" };

export const STRINGS = {
  en: {
    title: "smoothjog pendant",
    "st.Idle": "Idle",
    "st.Jog": "Jog",
    "st.Run": "Run",
    "st.Hold": "Hold",
    "st.Alarm": "Alarm",
    "st.Door": "Door",
    "st.Home": "Home",
    "st.Check": "Check",
    "st.Sleep": "Sleep",
    "st.Unknown": "Unknown",
    "conn.aria": "Connection to smoothjog",
    "conn.connecting": "connecting",
    "conn.up": "connected",
    "conn.down": "reconnecting",
    "link.aria": "Link quality: round trip to smoothjog",
    "link.title": "Round trip to smoothjog, and the longest pause of this page's own thread",
    "link.rtt": "{ms} ms",
    "link.detail": "round trip {ms} ms (worst {max} ms); this page paused up to {page} ms",
    "notice.frozen": "jog stopped: this page did not respond for {ms} ms; release and press again",
    "notice.tripped": "release the controls, then press again to jog",
    "state.aria": "Machine state",
    "role.aria": "Role of this pendant",
    "role.controller": "in control",
    "role.watcher": "watching",
    "take.label": "Take control",
    "take.aria": "Take control of the machine from the other pendant",
    "lang.aria": "Language",
    "status.aria": "Machine status and what to do",
    "status.ready": "Ready to jog.",
    "notice.aria": "Notices",
    "sticks.aria": "Jog sticks",
    "stick.xy.aria": "X Y jog stick: drag to jog X and Y, lift to stop",
    "stick.z.aria": "Z jog stick: drag up or down to jog Z, lift to stop",
    "speed.aria": "Speed",
    "speed.label": "Speed",
    "speed.slider.aria": "Jog speed in percent of the maximum",
    "ratios.label": "Axis speed ratio",
    "ratios.aria": "Per-axis speed ratios: the top speed of each axis as a fraction of its maximum",
    "ratio.aria": "{axis} speed ratio, above 0 and at most 1",
    "inertial.label": "Inertial",
    "inertial.aria": "Inertial mode: a flick keeps moving and slows down, a tap stops",
    "stop.label": "STOP",
    "stop.aria": "Stop all jogging now",
    "steps.aria": "Step jog",
    "steps.size.aria": "Step size",
    "steps.size.item": "Step size {size}",
    "steps.selected.aria": "Selected step size",
    "steps.rounded": "moves {size} (motor steps of {res})",
    "step.aria": "Step {axis} {sign}",
    "sign.plus": "plus",
    "sign.minus": "minus",
    "dro.aria": "Position readout",
    "dro.axis": "Axis",
    "dro.work": "Work",
    "dro.machine": "Mach.",
    "dro.stop": "Stop at",
    "dro.work.aria": "{axis} work position",
    "dro.machine.aria": "{axis} machine position",
    "dro.stop.aria": "{axis} predicted stop point",
    "meta.units.aria": "Display units",
    "meta.feed": "feed",
    "meta.feed.aria": "Feed rate reported by the controller",
    "meta.queue": "queue",
    "meta.queue.aria": "Jog queue",
    "meta.queue.value": "{blocks} blk, {len}",
    "meta.firmware.aria": "Firmware",
    "meta.modal": "modes",
    "meta.modal.aria": "Parser modes the controller reports ($G)",
    "top.title": "Top view",
    "top.aria": "Top view: machine position, predicted stop point, soft limits and keep-out zones",
    "top.grid": "grid {len}",
    "top.zoom.in": "Zoom in",
    "top.zoom.out": "Zoom out",
    "top.zoom.fit": "Fit",
    "top.follow": "Follow",
    "plot.title": "Speed",
    "plot.commanded": "commanded",
    "plot.actual": "reported",
    "plot.aria": "Commanded and reported speed over the last 10 seconds",
    "plot.window": "{unit} · last {s} s",
    "machine.title": "Machine",
    "machine.aria": "Machine control",
    "machine.home": "Home",
    "machine.home.aria": "Run the homing cycle ($H)",
    "machine.unlock": "Unlock",
    "machine.unlock.aria": "Unlock the controller without homing ($X)",
    "machine.unlock.warn": "Unlock trusts a position that may be wrong; home if you can.",
    "machine.reset": "Reset",
    "machine.reset.aria": "Soft reset the controller (Ctrl-X)",
    "machine.zero": "Zero {axis}",
    "machine.zero.aria": "Set work zero of {axis} here",
    "machine.zero.all": "Zero all",
    "machine.zero.all.aria": "Set work zero of every axis here",
    "machine.goto": "Go to zero",
    "machine.goto.aria": "Go to work zero: Z up to a safe height first, then X and Y, then Z",
    "machine.wcs": "Work system",
    "machine.wcs.aria": "Active work coordinate system",
    "machine.offset": "offset {values}",
    "machine.feed": "Feed override",
    "machine.rapid": "Rapid override",
    "machine.ov.aria": "{kind} override {step}",
    "machine.ov.feed": "feed",
    "machine.ov.rapid": "rapid",
    "machine.running": "Running: {what}",
    "console.title": "Console",
    "console.aria": "Console: send a line to the controller",
    "console.input.aria": "Line to send; arrow up and down for history",
    "console.placeholder": "$G, G0 X10 …",
    "console.send": "Send",
    "console.log.aria": "Console output",
    "console.ok": "ok",
    "settings.title": "Settings",
    "settings.keys": "Keys (hold to jog)",
    "settings.keys.reset": "Reset keys",
    "settings.keys.reset.aria": "Reset key bindings to the defaults",
    "settings.key": "{action}: {code}",
    "settings.key.aria": "Key for {action}: {code}. Press to change.",
    "settings.key.listen": "{action}: press a key…",
    "settings.sticks": "Sticks and gamepad",
    "settings.deadzone": "Deadzone",
    "settings.deadzone.aria": "Stick deadzone, 0 to 0.5",
    "settings.expo": "Expo",
    "settings.expo.aria": "Stick expo curve, 0 linear to 1 cubic",
    "settings.gp.deadman": "Gamepad dead-man button",
    "settings.gp.deadman.aria": "Require the gamepad dead-man button for any motion",
    "settings.gp.button": "button #",
    "settings.gp.button.aria": "Gamepad dead-man button number",
    "settings.range": "{name} must be between {lo} and {hi}.",
    "gamepad.none": "No gamepad",
    "gamepad.some": "Gamepad: {id}",
    "reason.offline": "Not connected to smoothjog; reconnecting…",
    "reason.watch.other": "Watching only: another pendant is in control.",
    "reason.watch.nobody": "Watching only: nobody is in control. Press Take control to jog.",
    "reason.waiting": "Waiting for the machine…",
    "reason.state": "Jogging is disabled while the machine is in {state}.",
    "ratio.bad": "Speed ratio {axis} must be above 0 and at most 1.",
    "result.failed": "{command} failed: {error}",
    "result.done": "{command}: done",
  },
  zh: {
    title: "smoothjog 手持控制器",
    "st.Idle": "空闲",
    "st.Jog": "点动",
    "st.Run": "运行",
    "st.Hold": "保持",
    "st.Alarm": "报警",
    "st.Door": "安全门",
    "st.Home": "回零中",
    "st.Check": "检查",
    "st.Sleep": "休眠",
    "st.Unknown": "未知",
    "conn.aria": "与 smoothjog 的连接",
    "conn.connecting": "连接中",
    "conn.up": "已连接",
    "conn.down": "重新连接中",
    "link.aria": "连接质量：到 smoothjog 的往返时间",
    "link.title": "到 smoothjog 的往返时间，以及本页面自身线程最长的停顿",
    "link.rtt": "{ms} 毫秒",
    "link.detail": "往返 {ms} 毫秒（最差 {max} 毫秒）；本页面最长停顿 {page} 毫秒",
    "notice.frozen": "点动已停止：本页面 {ms} 毫秒没有响应；请松开后重新按下",
    "notice.tripped": "请松开所有控制，然后重新按下以点动",
    "state.aria": "机器状态",
    "role.aria": "本控制器的角色",
    "role.controller": "控制中",
    "role.watcher": "仅观看",
    "take.label": "接管控制",
    "take.aria": "从另一个控制器接管机器",
    "lang.aria": "语言",
    "status.aria": "机器状态与处理办法",
    "status.ready": "可以点动。",
    "notice.aria": "通知",
    "sticks.aria": "点动摇杆",
    "stick.xy.aria": "XY 点动摇杆：拖动以点动 X 和 Y，松开即停",
    "stick.z.aria": "Z 点动摇杆：上下拖动以点动 Z，松开即停",
    "speed.aria": "速度",
    "speed.label": "速度",
    "speed.slider.aria": "点动速度，占最大速度的百分比",
    "ratios.label": "各轴速度比",
    "ratios.aria": "各轴速度比：每个轴的最高速度占其最大速度的比例",
    "ratio.aria": "{axis} 轴速度比，大于 0 且不超过 1",
    "inertial.label": "惯性",
    "inertial.aria": "惯性模式：快速拨动后继续移动并减速，轻点即停",
    "stop.label": "停止",
    "stop.aria": "立即停止所有点动",
    "steps.aria": "步进点动",
    "steps.size.aria": "步长",
    "steps.size.item": "步长 {size}",
    "steps.selected.aria": "当前步长",
    "steps.rounded": "实际移动 {size}（电机步距 {res}）",
    "step.aria": "{axis} 轴{sign}向步进",
    "sign.plus": "正",
    "sign.minus": "负",
    "dro.aria": "位置显示",
    "dro.axis": "轴",
    "dro.work": "工件",
    "dro.machine": "机械",
    "dro.stop": "停于",
    "dro.work.aria": "{axis} 轴工件坐标",
    "dro.machine.aria": "{axis} 轴机械坐标",
    "dro.stop.aria": "{axis} 轴预计停止位置",
    "meta.units.aria": "显示单位",
    "meta.feed": "进给",
    "meta.feed.aria": "控制器报告的进给速度",
    "meta.queue": "队列",
    "meta.queue.aria": "点动队列",
    "meta.queue.value": "{blocks} 段，{len}",
    "meta.firmware.aria": "固件",
    "meta.modal": "模态",
    "meta.modal.aria": "控制器报告的解析器模态（$G）",
    "top.title": "俯视图",
    "top.aria": "俯视图：机器位置、预计停止点、软限位与禁入区",
    "top.grid": "网格 {len}",
    "top.zoom.in": "放大",
    "top.zoom.out": "缩小",
    "top.zoom.fit": "全图",
    "top.follow": "跟随",
    "plot.title": "速度",
    "plot.commanded": "指令",
    "plot.actual": "实际（报告）",
    "plot.aria": "最近 10 秒的指令速度与报告速度",
    "plot.window": "{unit} · 最近 {s} 秒",
    "machine.title": "机器",
    "machine.aria": "机器控制",
    "machine.home": "回零",
    "machine.home.aria": "执行回零（$H）",
    "machine.unlock": "解锁",
    "machine.unlock.aria": "不回零直接解锁控制器（$X）",
    "machine.unlock.warn": "解锁会信任一个可能不准的位置；能回零就先回零。",
    "machine.reset": "复位",
    "machine.reset.aria": "软复位控制器（Ctrl-X）",
    "machine.zero": "{axis} 置零",
    "machine.zero.aria": "把当前位置设为 {axis} 轴工件零点",
    "machine.zero.all": "全部置零",
    "machine.zero.all.aria": "把当前位置设为所有轴的工件零点",
    "machine.goto": "回工件零点",
    "machine.goto.aria": "回工件零点：先把 Z 抬到安全高度，再移 X 和 Y，最后降 Z",
    "machine.wcs": "工件坐标系",
    "machine.wcs.aria": "当前工件坐标系",
    "machine.offset": "偏移 {values}",
    "machine.feed": "进给倍率",
    "machine.rapid": "快移倍率",
    "machine.ov.aria": "{kind}倍率 {step}",
    "machine.ov.feed": "进给",
    "machine.ov.rapid": "快移",
    "machine.running": "正在执行：{what}",
    "console.title": "控制台",
    "console.aria": "控制台：向控制器发送一行",
    "console.input.aria": "要发送的行；上下方向键翻历史",
    "console.placeholder": "$G、G0 X10 …",
    "console.send": "发送",
    "console.log.aria": "控制台输出",
    "console.ok": "完成",
    "settings.title": "设置",
    "settings.keys": "按键（按住点动）",
    "settings.keys.reset": "恢复默认按键",
    "settings.keys.reset.aria": "把按键绑定恢复为默认",
    "settings.key": "{action}：{code}",
    "settings.key.aria": "{action} 的按键：{code}。点击更改。",
    "settings.key.listen": "{action}：请按一个键…",
    "settings.sticks": "摇杆与手柄",
    "settings.deadzone": "死区",
    "settings.deadzone.aria": "摇杆死区，0 到 0.5",
    "settings.expo": "曲线",
    "settings.expo.aria": "摇杆曲线，0 为线性，1 为三次",
    "settings.gp.deadman": "手柄安全按钮",
    "settings.gp.deadman.aria": "任何移动都须按住手柄安全按钮",
    "settings.gp.button": "按钮编号",
    "settings.gp.button.aria": "手柄安全按钮的编号",
    "settings.range": "{name} 必须在 {lo} 到 {hi} 之间。",
    "gamepad.none": "没有手柄",
    "gamepad.some": "手柄：{id}",
    "reason.offline": "未连接到 smoothjog，正在重连…",
    "reason.watch.other": "仅观看：另一个控制器正在控制。",
    "reason.watch.nobody": "仅观看：目前无人控制。点“接管控制”即可点动。",
    "reason.waiting": "等待机器…",
    "reason.state": "机器处于 {state} 状态，不能点动。",
    "ratio.bad": "{axis} 轴速度比必须大于 0 且不超过 1。",
    "result.failed": "{command} 失败：{error}",
    "result.done": "{command}：完成",
  },
};

// Grbl's alarm and error codes (firmware-facts §5.6, §5.7): what happened and what to do.
const ALARMS_ZH = {
  1: "硬限位触发：位置可能已丢失，请复位后重新回零",
  2: "软限位：目标超出行程，位置仍可信，解锁即可",
  3: "运动中复位：位置可能已丢失，请重新回零",
  4: "探针失败：探针在开始前已触发",
  5: "探针失败：行程内未触碰到探针",
  6: "回零失败：回零中途被复位",
  7: "回零失败：回零中安全门被打开",
  8: "回零失败：退离后限位开关仍未松开",
  9: "回零失败：搜索距离内未找到限位开关",
  10: "回零失败：未找到第二个双轴限位开关",
};
const ERRORS_ZH = {
  1: "缺少字母",
  2: "数值格式错误",
  3: "无效的 $ 命令",
  4: "数值不能为负",
  5: "未启用回零（$22=0）",
  8: "机器不空闲，命令被拒绝",
  9: "报警或点动中，G 代码被锁定",
  10: "软限位需要先启用回零",
  11: "行过长",
  15: "点动目标超出行程",
  16: "点动命令含不允许的 G/M 代码",
  20: "不支持的命令或字母",
  21: "模态组冲突",
  22: "未指定进给速度",
  24: "一个程序段中有两个需要轴字的命令",
  25: "重复的字",
  26: "缺少轴字",
  33: "无效的目标",
  36: "程序段中有多余的字",
};

// Server sentences in the Chinese page, tried in order; {1}... are the captured parts.
const SERVER_ZH = [
  [/^the controller is in Alarm: unlock with \$X or home with \$H first$/, "控制器处于报警状态：请用 $X 解锁或用 $H 回零"],
  [/^the controller is in feed hold: resume \(~\) or reset before jogging$/, "控制器处于进给保持：点动前请继续（~）或复位"],
  [/^the safety door is open: close it and resume \(~\) before jogging$/, "安全门已打开：关上并继续（~）后才能点动"],
  [/^the controller is in check mode \(\$C\): leave it before jogging$/, "控制器处于检查模式（$C）：退出后才能点动"],
  [/^the controller is running a program: jogging waits until it is idle$/, "控制器正在运行程序：空闲后才能点动"],
  [/^the controller is homing: jogging waits until it is done$/, "控制器正在回零：完成后才能点动"],
  [/^the controller is asleep: reset it to wake it$/, "控制器处于休眠：复位以唤醒"],
  [/^the controller is in state (\w+)$/, "控制器处于 {1} 状态"],
  [/^waiting for the controller's first status report$/, "等待控制器的第一份状态报告"],
  [/^soft limits are on but the machine looks unhomed .*home it with \$H first$/, "已开启软限位，但机器似乎未回零（机械坐标为 0,0,0，任何正向点动都会报 error:15）：请先用 $H 回零"],
  [/^the connection to the controller is lost$/, "与控制器的连接已断开"],
  [/^check the cable and restart$/, "请检查线缆后重启"],
  [/^jogging waits: (homing|unlocking|resetting|setting work zero|a console line|selecting G5\d) is running$/, "点动需等待：{1} 正在执行"],
  [/^wait: (.+) has not finished$/, "请等待：{1} 尚未完成"],
  [/^the machine is moving: press STOP and wait until it stands still$/, "机器正在移动：请按停止并等它停稳"],
  [/^this pendant is watching only; press Take control to drive the machine$/, "本控制器仅观看；点“接管控制”才能操作机器"],
  [/^jog stopped: no heartbeat from this pendant for (\d+) ms \(weak Wi-Fi or a busy device\?\)$/, "点动已停止：本控制器 {1} 毫秒没有心跳（Wi-Fi 信号弱或设备太忙？）"],
  [/^homing is not enabled on this controller .*$/, "此控制器未启用回零（$22=0）：没有可回零的开关；只有机器装了开关时才设 $22=1"],
  [/^the work offset is not known yet; wait for the next status report$/, "工件偏移尚未知道：请等下一份状态报告"],
  [/^jogging stopped: (.+)$/, "点动已停止：{1}"],
  [/^jog refused: (.+)$/, "点动被拒绝：{1}"],
  [/^another (.+) is holding a jog; control can pass once it releases$/, "另一个输入正在点动；它松开后才能接管"],
  [/^this (.+) is watching only; take control to drive the machine$/, "本控制器仅观看；接管控制后才能操作机器"],
  [/^jogging is disabled: (.+)$/, "不能点动：{1}"],
  [/^type a line to send, for example \$G or G0 X10$/, "请输入要发送的行，例如 $G 或 G0 X10"],
  [/^the line is (\d+) characters; this controller reads at most (\d+)$/, "该行有 {1} 个字符；此控制器最多读取 {2} 个"],
];

const WHAT_ZH = {
  homing: "回零",
  unlocking: "解锁",
  resetting: "复位",
  "setting work zero": "置零",
  "a console line": "控制台命令",
};

let lang = "en";

/** The language to start in: the stored choice, else the browser's, else English. */
export function pickLanguage(stored) {
  if (stored && stored in STRINGS) return stored;
  for (const l of navigator.languages || [navigator.language || "en"]) {
    const base = String(l).toLowerCase().split("-")[0];
    if (base in STRINGS) return base;
  }
  return "en";
}

export function setLanguage(l) {
  lang = l in STRINGS ? l : "en";
  document.documentElement.lang = lang === "zh" ? "zh-CN" : "en";
}

export function language() {
  return lang;
}

/** The string for key in the page's language, with {name} filled from params. */
export function t(key, params = {}) {
  const table = STRINGS[lang];
  let s = table[key] ?? STRINGS.en[key] ?? key;
  for (const [k, v] of Object.entries(params)) s = s.replaceAll(`{${k}}`, String(v));
  return s;
}

/** Fill every data-i18n, data-i18n-aria and data-i18n-title element under root. */
export function applyStrings(root = document) {
  for (const el of root.querySelectorAll("[data-i18n]")) el.textContent = t(el.dataset.i18n);
  for (const el of root.querySelectorAll("[data-i18n-aria]")) {
    el.setAttribute("aria-label", t(el.dataset.i18nAria));
  }
  for (const el of root.querySelectorAll("[data-i18n-title]")) el.title = t(el.dataset.i18nTitle);
  for (const el of root.querySelectorAll("[data-i18n-placeholder]")) {
    el.placeholder = t(el.dataset.i18nPlaceholder);
  }
  document.title = t("title");
}

function fill(template, match) {
  return template.replace(/\{(\d)\}/g, (_, i) => {
    const part = match[Number(i)] ?? "";
    return WHAT_ZH[part] ?? translateServer(part);
  });
}

/** A sentence from the server in the page's language (as sent when no pattern knows it). */
export function translateServer(text) {
  const s = String(text ?? "");
  if (lang !== "zh" || s === "") return s;
  const code = /^(ALARM|error):(\d+) \(/.exec(s);
  if (code) {
    const n = Number(code[2]);
    const zh = code[1] === "ALARM" ? ALARMS_ZH[n] : ERRORS_ZH[n];
    if (zh) return `${code[1] === "ALARM" ? "报警" : "错误"} ${n}：${zh}`;
  }
  for (const [pattern, template] of SERVER_ZH) {
    const m = pattern.exec(s);
    if (m) return fill(template, m);
  }
  return s;
}
