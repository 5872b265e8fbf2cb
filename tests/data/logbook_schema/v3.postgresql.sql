-- logbook schema 3 as dischargelab 1c4865b creates it (postgresql), one statement per block
CREATE TABLE blobs (
	sha256 VARCHAR(64) NOT NULL, 
	compression VARCHAR(10) NOT NULL, 
	size_bytes BIGINT NOT NULL, 
	data BYTEA NOT NULL, 
	PRIMARY KEY (sha256)
)
;
CREATE TABLE logbook_meta (
	key VARCHAR(64) NOT NULL, 
	value TEXT NOT NULL, 
	PRIMARY KEY (key)
)
;
CREATE TABLE packs (
	id SERIAL NOT NULL, 
	name VARCHAR(200) NOT NULL, 
	"label_capacity_Ah" FLOAT, 
	chemistry VARCHAR(20), 
	cells INTEGER, 
	created_at VARCHAR(40) NOT NULL, 
	PRIMARY KEY (id), 
	UNIQUE (name)
)
;
CREATE TABLE sources (
	id SERIAL NOT NULL, 
	sha256 VARCHAR(64) NOT NULL, 
	pack_id INTEGER NOT NULL, 
	file_name VARCHAR(500) NOT NULL, 
	path TEXT, 
	size_bytes BIGINT NOT NULL, 
	format VARCHAR(40) NOT NULL, 
	added_at VARCHAR(40) NOT NULL, 
	options_json TEXT NOT NULL, 
	notes_json TEXT NOT NULL, 
	PRIMARY KEY (id), 
	UNIQUE (sha256), 
	FOREIGN KEY(pack_id) REFERENCES packs (id)
)
;
CREATE TABLE events (
	id SERIAL NOT NULL, 
	source_id INTEGER NOT NULL, 
	idx INTEGER NOT NULL, 
	pack_id INTEGER NOT NULL, 
	kind VARCHAR(20) NOT NULL, 
	start_time VARCHAR(40), 
	cycle INTEGER, 
	duration_s FLOAT, 
	"discharged_Ah" FLOAT, 
	"discharged_Wh" FLOAT, 
	"mean_current_A" FLOAT, 
	"max_current_A" FLOAT, 
	"rest_voltage_V" FLOAT, 
	"rest_after_V" FLOAT, 
	rest_after_s FLOAT, 
	"min_voltage_V" FLOAT, 
	"end_voltage_V" FLOAT, 
	"end_current_A" FLOAT, 
	resistance_ohm FLOAT, 
	resistance_low_ohm FLOAT, 
	resistance_high_ohm FLOAT, 
	"temperature_start_C" FLOAT, 
	"temperature_max_C" FLOAT, 
	"ambient_C" FLOAT, 
	"cell_spread_V" FLOAT, 
	reaches_knee BOOLEAN NOT NULL, 
	cells INTEGER, 
	samples INTEGER NOT NULL, 
	curve_json TEXT NOT NULL, 
	details_json TEXT, 
	PRIMARY KEY (id), 
	CONSTRAINT uq_events_source_idx UNIQUE (source_id, idx), 
	FOREIGN KEY(source_id) REFERENCES sources (id), 
	FOREIGN KEY(pack_id) REFERENCES packs (id)
)
;
CREATE TABLE models (
	id SERIAL NOT NULL, 
	pack_id INTEGER NOT NULL, 
	fitted_at VARCHAR(40) NOT NULL, 
	reference_event_id INTEGER, 
	"capacity_Ah" FLOAT, 
	resistance_ohm FLOAT, 
	battery_json TEXT NOT NULL, 
	PRIMARY KEY (id), 
	FOREIGN KEY(pack_id) REFERENCES packs (id), 
	FOREIGN KEY(reference_event_id) REFERENCES events (id)
)
;
INSERT INTO logbook_meta (key, value) VALUES ('schema_version', '3')
;
